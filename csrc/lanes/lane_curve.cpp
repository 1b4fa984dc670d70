#include "lanes/lane_curve.hpp"

#include "lanes/road_geometry.hpp"

#include <opencv2/core.hpp>

#include <algorithm>
#include <array>
#include <cmath>

namespace hw {

namespace {

constexpr int kMaxBoundaries = 6;

// Boundary i as x(d) = a + b d + e d^2 + c / d, d = y - y_h.
struct Curve {
    float a = 0.f, b = 0.f, e = 0.f;
    float x(float d, float c) const { return a + b * d + e * d * d + c / d; }
};

// Least squares over the points assigned to each boundary: unknowns (a_i, b_i, e_i) per fitted
// boundary and the shared c, with pseudo-measurements c = c_prior of weight w_prior and e_i = 0 of
// weight w_e (points). Solved in t = d / D (D: d of the bottom row), x = a + b' t + e' t^2 + c' / t,
// so that the normal equations are well conditioned (d^2 and 1/d differ by 10 orders at 720 rows);
// b = b' / D, e = e' / D^2, c = c' D. Normal equations N u = r, u = (a_0, b'_0, e'_0, a_1, ..., c').
bool solve(const std::vector<MarkingPoint> &pts, const std::vector<int> &owner, int n, float y_h, float D,
           float c_prior, float w_prior, float w_e, float contrast_power, bool shared_a,
           std::array<Curve, kMaxBoundaries> &curves, float &c) {
    // shared_a: one a for every boundary (the flat road's x_c + fx psi), unknowns (a, b'_0, e'_0, b'_1, e'_1, ...,
    // c'); else one a per boundary, (a_0, b'_0, e'_0, a_1, ..., c').
    const int dim = shared_a ? 2 * n + 2 : 3 * n + 1;
    cv::Mat N = cv::Mat::zeros(dim, dim, CV_64F), r = cv::Mat::zeros(dim, 1, CV_64F);
    // Point weights: w_j = min(1, contrast_j / median contrast of the fitted points)^power (power 0: all 1). A
    // seam's bright lip or the texture beside the paint weighs less than the paint; a point brighter than the
    // median (a vehicle's lamp or chrome inside the corridor) weighs no more than the paint.
    std::vector<float> cs;
    for (size_t j = 0; j < pts.size(); ++j)
        if (owner[j] >= 0) cs.push_back(pts[j].contrast);
    if (cs.empty()) return false;
    std::nth_element(cs.begin(), cs.begin() + long(cs.size() / 2), cs.end());
    const double c_med = std::max(1.0, double(cs[cs.size() / 2]));
    for (size_t j = 0; j < pts.size(); ++j) {
        const int i = owner[j];
        if (i < 0) continue;
        const double w = std::pow(std::min(1.0, double(pts[j].contrast) / c_med), double(contrast_power));
        const double t = (pts[j].y - y_h) / D, g[4] = {1.0, t, t * t, 1.0 / t};
        int idx[4] = {3 * i, 3 * i + 1, 3 * i + 2, dim - 1};
        if (shared_a) { idx[0] = 0; idx[1] = 1 + 2 * i; idx[2] = 2 + 2 * i; }
        for (int u = 0; u < 4; ++u) {
            r.at<double>(idx[u]) += w * g[u] * pts[j].x;
            for (int v = 0; v < 4; ++v) N.at<double>(idx[u], idx[v]) += w * g[u] * g[v];
        }
    }
    for (int i = 0; i < n; ++i) {
        const int ie = shared_a ? 2 + 2 * i : 3 * i + 2;
        N.at<double>(ie, ie) += w_e;
    }
    N.at<double>(dim - 1, dim - 1) += w_prior;
    r.at<double>(dim - 1) += w_prior * c_prior / D;
    cv::Mat u;
    if (!cv::solve(N, r, u, cv::DECOMP_CHOLESKY)) return false;
    for (int i = 0; i < n; ++i) {
        const int ia = shared_a ? 0 : 3 * i, ib = shared_a ? 1 + 2 * i : 3 * i + 1;
        curves[size_t(i)] = {float(u.at<double>(ia)), float(u.at<double>(ib) / D),
                             float(u.at<double>(ib + 1) / (double(D) * D))};
    }
    c = float(u.at<double>(dim - 1) * D);
    return std::isfinite(c);
}

} // namespace

void fit_lane_curves(const std::vector<MarkingPoint> &pts, float y_h, const CameraParams &cam, float lane_width_m,
                     const LaneCurveParams &p, LaneCurveState &state, LaneModel &m, bool shared_a) {
    LaneBoundary *all[kMaxBoundaries] = {&m.out_left, &m.adj_left, &m.ego_left, &m.ego_right, &m.adj_right, &m.out_right};
    std::array<LaneBoundary *, kMaxBoundaries> bs{};
    int n = 0;
    for (auto *b : all)
        if (b->valid && b->bottom.y - y_h > 1.f && b->top.y - y_h > 1.f) bs[size_t(n++)] = b;
    if (!p.enabled || n == 0 || !std::isfinite(y_h)) return;
    m.far_row = far_row(cam, y_h, p);

    // Straight start: each boundary's line in d-form (c = 0).
    std::array<Curve, kMaxBoundaries> curves{};
    for (int i = 0; i < n; ++i) {
        const LaneBoundary &b = *bs[size_t(i)];
        const float k = (b.top.x - b.bottom.x) / (b.top.y - b.bottom.y);
        curves[size_t(i)] = {b.bottom.x - k * (b.bottom.y - y_h), k};
    }
    const float c_max = float(cam.fx * cam.fy * cam.height_m / (2.0 * p.min_radius_m));
    const float c_prior = state.known ? state.c : 0.f;
    float c = c_prior;
    const float d_near = float(cam.fy * cam.height_m / p.near_range_m);
    const float sig3 = 3.f * float(p.residual_sigma_px);

    // Each point to the nearest boundary within the corridor (-1: none); pass 0 near rows only.
    std::vector<int> owner(pts.size(), -1);
    std::array<int, kMaxBoundaries> count{};
    auto assign = [&](int pass, float cc, const std::array<Curve, kMaxBoundaries> &cv_, const std::vector<int> *prev_owner) {
        count.fill(0);
        for (size_t j = 0; j < pts.size(); ++j) {
            owner[j] = -1;
            const float d = pts[j].y - y_h;
            if (d <= 1.f || (pass == 0 && d < d_near)) continue;
            const float tol = std::max(float(p.min_corridor_px),
                                       float(p.corridor_lanes) * lane_width_m * px_per_m(cam, y_h, pts[j].y));
            float best = pass == 2 ? sig3 : tol;
            for (int i = 0; i < n; ++i) {
                if (pass == 2 && (*prev_owner)[j] != i) continue;
                const float e = std::fabs(pts[j].x - cv_[size_t(i)].x(d, cc));
                if (e < best) { best = e; owner[j] = i; }
            }
            if (owner[j] >= 0) ++count[size_t(owner[j])];
        }
    };
    // Boundaries with too few points leave the fit; their indices are compacted for solve().
    auto fit = [&]() -> bool {
        std::array<int, kMaxBoundaries> slot{};
        int m_fit = 0;
        for (int i = 0; i < n; ++i) slot[size_t(i)] = count[size_t(i)] >= p.min_points ? m_fit++ : -1;
        if (m_fit == 0) return false;
        std::vector<int> o(owner.size(), -1);
        for (size_t j = 0; j < owner.size(); ++j)
            if (owner[j] >= 0) o[j] = slot[size_t(owner[j])];
        std::array<Curve, kMaxBoundaries> sol{};
        float cs;
        // e' = 1 (1 px at the bottom row) weighs as much as prior_e_points points; c' likewise.
        if (!solve(pts, o, m_fit, y_h, float(cam.height) - y_h, c_prior, float(p.prior_points),
                   float(p.prior_e_points), float(p.contrast_power), shared_a, sol, cs))
            return false;
        c = std::clamp(cs, -c_max, c_max);
        for (int i = 0; i < n; ++i)
            if (slot[size_t(i)] >= 0) curves[size_t(i)] = sol[size_t(slot[size_t(i)])];
        return true;
    };

    std::array<char, kMaxBoundaries> fitted{};
    assign(0, 0.f, curves, nullptr);
    bool ok = fit();
    if (ok) {
        assign(1, c, curves, nullptr);
        ok = fit();
    }
    if (ok) {
        const std::vector<int> prev = owner;
        assign(2, c, curves, &prev);
        ok = fit();
    }
    if (!ok) c = c_prior;
    for (int i = 0; i < n; ++i) fitted[size_t(i)] = ok && count[size_t(i)] >= p.min_points;
    state.c = c;
    state.known = state.known || ok;

    for (int i = 0; i < n; ++i) {
        LaneBoundary &b = *bs[size_t(i)];
        const float db = b.bottom.y - y_h, dt = b.top.y - y_h;
        if (fitted[size_t(i)]) {
            b.bottom.x = curves[size_t(i)].x(db, c);
            b.top.x = curves[size_t(i)].x(dt, c);
        } else {
            // Bent around the tracked line, tangent to it at the bottom row:
            // x = line(y) + c (1/d - 2/d_b + d/d_b^2) (value and slope unchanged at d = d_b).
            b.top.x += c * (1.f / dt - 2.f / db + dt / (db * db));
        }
        b.curve = c;
        b.bend = fitted[size_t(i)] ? curves[size_t(i)].e : 0.f;
        b.curve_row = y_h;
    }
}

float far_row(const CameraParams &cam, float y_h, const LaneCurveParams &p) {
    return std::isfinite(y_h) ? row_at_range(cam, y_h, float(p.far_range_m)) : kNaN;
}

void sample_boundary(const LaneBoundary &b, float y_far, int n, float *xs, float *ys) {
    const bool beyond = std::isfinite(y_far) && y_far < b.top.y && std::isfinite(b.curve_row) && y_far > b.curve_row;
    const float y_end = beyond ? y_far : b.top.y;
    const float db = b.bottom.y - b.curve_row, dt = y_end - b.curve_row;
    const bool log_rows = std::isfinite(b.curve_row) && db > 0.f && dt > 0.f;
    for (int j = 0; j < n; ++j) {
        const float s = float(j) / float(n - 1);
        const float y = log_rows ? b.curve_row + db * std::pow(dt / db, s) : b.bottom.y + s * (y_end - b.bottom.y);
        ys[j] = y;
        xs[j] = b.curve_x(y);
    }
    ys[0] = b.bottom.y;  // exact bottom
    xs[0] = b.bottom.x;
}

} // namespace hw

