#include "lanes/lane_assembly.hpp"

#include <opencv2/imgproc.hpp>

#include <algorithm>
#include <cmath>
#include <stdexcept>

namespace hw {

namespace {

ImageLine line_of(const LaneBoundary &b) {
    ImageLine l;
    l.y_ref = b.bottom.y;
    l.x_ref = b.bottom.x;
    l.k = (b.top.x - b.bottom.x) / (b.top.y - b.bottom.y);
    return l;
}

// Point (x, y) minimising sum w_i d_i^2, d_i the distance to line i: with the line written as
// a x + b y = c, (a, b) = (1, -k) / sqrt(1 + k^2), the 2x2 normal equations.
bool least_squares_point(const std::vector<LaneCandidate> &c, const std::vector<char> &use, cv::Point2f &p) {
    double saa = 0, sab = 0, sbb = 0, sac = 0, sbc = 0;
    for (size_t i = 0; i < c.size(); ++i) {
        if (!use[i]) continue;
        const ImageLine &l = c[i].line;
        const double n = std::sqrt(1.0 + double(l.k) * l.k);
        const double a = 1.0 / n, b = -l.k / n, cc = (l.x_ref - double(l.k) * l.y_ref) / n, w = c[i].weight;
        saa += w * a * a; sab += w * a * b; sbb += w * b * b; sac += w * a * cc; sbc += w * b * cc;
    }
    const double det = saa * sbb - sab * sab;
    if (std::fabs(det) < 1e-9 * (saa + sbb) * (saa + sbb) || det == 0.0) return false;
    p.x = float((sac * sbb - sab * sbc) / det);
    p.y = float((saa * sbc - sab * sac) / det);
    return true;
}

} // namespace

std::vector<cv::Point> clip_to_image(const std::vector<cv::Point2f> &quad, cv::Size size) {
    const std::vector<cv::Point2f> img{{0.f, 0.f}, {float(size.width - 1), 0.f},
                                       {float(size.width - 1), float(size.height - 1)},
                                       {0.f, float(size.height - 1)}};
    std::vector<cv::Point2f> clipped;
    cv::intersectConvexConvex(quad, img, clipped, true);
    std::vector<cv::Point> out;
    for (const auto &q : clipped) out.emplace_back(int(std::lround(q.x)), int(std::lround(q.y)));
    return out;
}

bool consensus_vanishing_point(const std::vector<LaneCandidate> &c, const HorizonPrior &hp, cv::Size size,
                               const LaneAssemblyParams &p, cv::Point2f &vp, std::vector<char> &inlier) {
    inlier.assign(c.size(), 1);
    const float tol = float(p.vp_inlier_frac) * float(size.width);
    const float x_window = 0.25f * float(size.width) + hp.tol_px;
    float best = 0.f;
    std::vector<char> use(c.size(), 0), best_use;
    // Every pair of lines that are not nearly parallel proposes its intersection; the proposal
    // with the largest weight of lines passing within tol of it wins.
    for (size_t i = 0; i < c.size(); ++i)
        for (size_t j = i + 1; j < c.size(); ++j) {
            if (std::fabs(std::atan(c[i].line.k) - std::atan(c[j].line.k)) < 0.035f) continue;  // 2 deg
            cv::Point2f q;
            if (!intersect(c[i].line, c[j].line, q)) continue;
            if (std::fabs(q.y - hp.row) > hp.tol_px || std::fabs(q.x - hp.vp_x) > x_window) continue;
            float score = 0.f;
            for (size_t l = 0; l < c.size(); ++l) {
                use[l] = distance(c[l].line, q) <= tol;
                score += use[l] ? c[l].weight : 0.f;
            }
            if (score > best) { best = score; best_use = use; vp = q; }
        }
    if (best_use.empty()) return false;
    cv::Point2f refined;
    if (least_squares_point(c, best_use, refined) && std::fabs(refined.y - hp.row) <= hp.tol_px) vp = refined;
    inlier = best_use;
    return true;
}

LaneAssignment assign_lanes(const std::vector<LaneCandidate> &c, const CameraParams &cam,
                            const LaneAssemblyParams &p, int prev_left_id, int prev_right_id,
                            float expected_width_k) {
    LaneAssignment a;
    const float lw = float(p.road.lane_width_m);
    const float w_min = float(p.min_lane_width_frac) * lw, w_max = float(p.max_lane_width_frac) * lw;
    const float hyst = float(p.hysteresis_m);
    std::vector<float> X(c.size());
    std::vector<char> is_left(c.size());
    for (size_t i = 0; i < c.size(); ++i) {
        X[i] = lateral_from_slope(cam, c[i].line.k);
        // Side of the camera, with hysteresis for last frame's ego boundaries (lane change).
        float split = 0.f;
        if (c[i].id >= 0 && c[i].id == prev_left_id) split = hyst;
        if (c[i].id >= 0 && c[i].id == prev_right_id) split = -hyst;
        is_left[i] = X[i] < split;
    }

    // Ego pair: one line each side, plausible width; score = evidence, discounted by the departure
    // from the expected width, with a bonus for last frame's pair (continuity).
    float best = 0.f;
    for (size_t l = 0; l < c.size(); ++l) {
        if (!is_left[l]) continue;
        for (size_t r = 0; r < c.size(); ++r) {
            if (is_left[r]) continue;
            const float w = X[r] - X[l];
            if (w < w_min || w > w_max) continue;
            float score = (c[l].weight + c[r].weight) * (1.f - 0.5f * std::fabs(w - lw) / lw);
            if (c[l].id >= 0 && c[l].id == prev_left_id && c[r].id == prev_right_id) score *= 1.5f;
            if (score > best) { best = score; a.ego_left = int(l); a.ego_right = int(r); }
        }
    }

    float width_m;
    if (a.ego_left >= 0) {
        width_m = X[size_t(a.ego_right)] - X[size_t(a.ego_left)];
        a.width_k = c[size_t(a.ego_right)].line.k - c[size_t(a.ego_left)].line.k;
    } else {
        // No pair: the best-supported line within one lane of the camera is one ego boundary.
        a.width_k = std::isfinite(expected_width_k) ? expected_width_k : slope_from_lateral(cam, lw);
        width_m = lateral_from_slope(cam, a.width_k);
        float best_single = 0.f;
        int pick = -1;
        for (size_t i = 0; i < c.size(); ++i) {
            if (std::fabs(X[i]) > std::min(w_max, width_m)) continue;
            float score = c[i].weight;
            if (c[i].id >= 0 && (c[i].id == prev_left_id || c[i].id == prev_right_id)) score *= 1.5f;
            if (score > best_single) { best_single = score; pick = int(i); }
        }
        if (pick < 0) return a;
        (is_left[size_t(pick)] ? a.ego_left : a.ego_right) = pick;
    }

    // Adjacent boundaries: lines one lane outside the ego lane, n = (X - X_left) / width ~ -1 or 2; the
    // outer ones one lane beyond, n ~ -2 or 3 (the grid from the ego lane's width: lanes of a road are alike).
    const float x_left = a.ego_left >= 0 ? X[size_t(a.ego_left)] : X[size_t(a.ego_right)] - width_m;
    const float grid[4] = {-1.f, 2.f, -2.f, 3.f};
    int *slot[4] = {&a.adj_left, &a.adj_right, &a.out_left, &a.out_right};
    float best_w[4] = {0.f, 0.f, 0.f, 0.f};
    for (size_t i = 0; i < c.size(); ++i) {
        if (int(i) == a.ego_left || int(i) == a.ego_right) continue;
        const float n = (X[i] - x_left) / width_m;
        for (int g = 0; g < (p.outer_lanes ? 4 : 2); ++g)
            if (std::fabs(n - grid[g]) < float(p.grid_tolerance) && c[i].weight > best_w[g]) {
                best_w[g] = c[i].weight;
                *slot[g] = int(i);
            }
    }
    // The grid continues only from a found adjacent boundary (a line two lanes out with nothing between
    // is as likely a shoulder or a barrier).
    if (a.adj_left < 0) a.out_left = -1;
    if (a.adj_right < 0) a.out_right = -1;
    return a;
}

void build_lane_model(const std::vector<LaneCandidate> &c, const LaneAssignment &a, cv::Point2f vp,
                      cv::Size size, const CameraParams &cam, const HorizonPrior &hp,
                      const LaneAssemblyParams &p, LaneModel &out) {
    if (size.height < 2) throw std::invalid_argument("build_lane_model: image too small");
    const float y_b = float(size.height - 1);
    cv::Point2f v = vp;
    if (a.ego_left >= 0 && a.ego_right >= 0) {
        cv::Point2f q;
        if (intersect(c[size_t(a.ego_left)].line, c[size_t(a.ego_right)].line, q)) v = q;
    }
    const float vp_row = std::isfinite(v.y) ? v.y : hp.row;
    const float y_t = std::min(y_b - 1.f, row_at_range(cam, vp_row, float(p.road_range_m)));

    auto fill = [&](int idx, LaneBoundary &b) {
        b = LaneBoundary();
        if (idx < 0) return;
        const LaneCandidate &lc = c[size_t(idx)];
        b.valid = true;
        b.observed = lc.observed;
        b.bottom = {lc.line.x_at(y_b), y_b};
        b.top = {lc.line.x_at(y_t), y_t};
    };
    fill(a.ego_left, out.ego_left);
    fill(a.ego_right, out.ego_right);
    fill(a.adj_left, out.adj_left);
    fill(a.adj_right, out.adj_right);
    fill(a.out_left, out.out_left);
    fill(a.out_right, out.out_right);
    out.valid = out.ego_left.valid && out.ego_right.valid;
    out.vanishing_point = v;
    out.road_polygon = road_polygon(out, a.width_k, size, cam, hp, p);
}

void ego_lane_metrics(const CameraParams &cam, LaneModel &m) {
    m.width_m = m.offset_m = kNaN;
    const cv::Point2f vp = m.vanishing_point;
    if (!m.valid || !std::isfinite(vp.x) || !std::isfinite(vp.y)) return;
    const float y = m.ego_left.bottom.y, ppm = px_per_m(cam, vp.y, y);
    if (ppm <= 0.f) return;
    const float xl = (m.ego_left.curve_x(y) - vp.x) / ppm, xr = (m.ego_right.curve_x(y) - vp.x) / ppm;
    m.width_m = xr - xl;
    m.offset_m = -float(cam.lateral_m) - 0.5f * (xl + xr);
}

std::vector<cv::Point> road_polygon(const LaneModel &m, float width_k, cv::Size size, const CameraParams &cam,
                                    const HorizonPrior &hp, const LaneAssemblyParams &p) {
    const float y_b = float(size.height - 1);
    cv::Point2f vp = m.vanishing_point;
    if (!std::isfinite(vp.x) || !std::isfinite(vp.y)) vp = {hp.vp_x, hp.row};
    const float dk = std::isfinite(width_k) ? width_k : slope_from_lateral(cam, float(p.road.lane_width_m));
    const float y_t = std::min(y_b - 1.f, row_at_range(cam, vp.y, float(p.road_range_m)));

    // Outer lines: the adjacent boundary where known, else the nearest known boundary shifted out
    // by the lanes between them (ego lane +- one lane when only the ego lane is known).
    const LaneBoundary *order[4] = {&m.adj_left, &m.ego_left, &m.ego_right, &m.adj_right};
    ImageLine left, right;
    bool have_left = false, have_right = false;
    for (int i = 0; i < 4 && !have_left; ++i)
        if (order[i]->valid) { left = shifted_by_lanes(line_of(*order[i]), -float(i), dk, vp); have_left = true; }
    for (int i = 3; i >= 0 && !have_right; --i)
        if (order[i]->valid) { right = shifted_by_lanes(line_of(*order[i]), float(3 - i), dk, vp); have_right = true; }

    if (!have_left) {
        // Camera model default: ego lane centred on the car (camera lateral_m right of the car's
        // centre), +- 1.5 lanes beyond the ego lane's boundaries, all meeting at the horizon prior.
        const float lw = float(p.road.lane_width_m), xc = -float(cam.lateral_m);
        vp = {hp.vp_x, hp.row};
        left = {vp.x, vp.y, slope_from_lateral(cam, xc - 2.f * lw)};
        right = {vp.x, vp.y, slope_from_lateral(cam, xc + 2.f * lw)};
    }
    const float top = std::min(y_b - 1.f, row_at_range(cam, vp.y, float(p.road_range_m)));
    const float yt = have_left ? y_t : top;
    float xl_t = left.x_at(yt), xr_t = right.x_at(yt);
    if (xl_t > xr_t) xl_t = xr_t = 0.5f * (xl_t + xr_t);
    const std::vector<cv::Point2f> quad{{left.x_at(y_b), y_b}, {xl_t, yt}, {xr_t, yt}, {right.x_at(y_b), y_b}};
    return clip_to_image(quad, size);
}

} // namespace hw
