#include "lanes/hough_lines.hpp"

#include <algorithm>
#include <cmath>
#include <stdexcept>

namespace hw {

namespace {

constexpr float kDeg = float(M_PI / 180.0);

// One image half: the points with lo <= x < hi vote for lines whose slope k = dx/dy lies in
// [k_lo, k_hi] (left half: leaning "/" plus a little "\", right half the mirror).
struct Half {
    float x_lo, x_hi;
    float theta_lo, theta_hi;  // rad; normal angle theta = -atan(k)
};

struct Peak {
    int votes, t, r;
};

// What a line must have to be kept.
struct Acceptance {
    int min_votes;    // supporting points
    float min_span;   // rows between the 10th and 90th percentile of the support
    float tol;        // px, perpendicular distance of a supporting point
    float y_ref;      // row the fitted lines refer to
};

// Least-squares line x = a + k (y - y_ref) through the unclaimed points within `tol`
// (perpendicular) of `guess` and inside the half; two passes so the second uses the refined line.
// The window's anchor (a known vanishing point) counts as `anchor_weight` extra points: a line
// fitted to one short dash gets its direction from the vanishing point, a long marking from its
// own points. `support` receives the indices of the supporting points. False if too few.
bool fit_line(const std::vector<MarkingPoint> &pts, const std::vector<char> &claimed, const Half &h,
              const ImageLine &guess, float tol, const HoughWindow &w, LaneLine &out,
              std::vector<size_t> &support) {
    ImageLine l = guess;
    std::vector<float> ys;
    const double wa = w.anchor_weight, ua = w.origin.y - l.y_ref, xa = w.origin.x;
    for (int pass = 0; pass < 2; ++pass) {
        double n = 0, su = 0, suu = 0, sx = 0, sux = 0;
        float y_min = 1e9f, y_max = -1e9f;
        ys.clear();
        support.clear();
        const float norm = std::sqrt(1.f + l.k * l.k);
        for (size_t i = 0; i < pts.size(); ++i) {
            const MarkingPoint &q = pts[i];
            if (claimed[i] || q.x < h.x_lo || q.x >= h.x_hi) continue;
            if (std::fabs(q.x - l.x_at(q.y)) > tol * norm) continue;
            const double u = q.y - l.y_ref;
            n += 1; su += u; suu += u * u; sx += q.x; sux += u * q.x;
            y_min = std::min(y_min, q.y);
            y_max = std::max(y_max, q.y);
            ys.push_back(q.y);
            support.push_back(i);
        }
        if (n < 2) return false;
        const double votes = n;
        n += wa; su += wa * ua; suu += wa * ua * ua; sx += wa * xa; sux += wa * ua * xa;
        const double det = n * suu - su * su;
        if (det <= 1e-6 * n * n) return false;
        // Normal equations of min sum w_i (x_i - a - k u_i)^2.
        const double k = (n * sux - su * sx) / det;
        const double a = (sx - k * su) / n;
        l.k = float(k);
        l.x_ref = float(a);
        out.line = l;
        out.votes = float(votes);
        out.y_min = y_min;
        out.y_max = y_max;
    }
    // Robust span: 10th to 90th percentile of the supporting rows.
    const size_t lo = ys.size() / 10, hi = ys.size() - 1 - ys.size() / 10;
    std::nth_element(ys.begin(), ys.begin() + long(lo), ys.end());
    const float p10 = ys[lo];
    std::nth_element(ys.begin(), ys.begin() + long(hi), ys.end());
    out.span = ys[hi] - p10;
    // Fit precision (the anchor, if any, is a point of weight wa at the origin's row).
    double sy = wa * w.origin.y;
    for (float y : ys) sy += y;
    const double n_eff = double(ys.size()) + wa, y_mean = sy / n_eff;
    double s_yy = wa * (w.origin.y - y_mean) * (w.origin.y - y_mean);
    for (float y : ys) s_yy += (y - y_mean) * (y - y_mean);
    out.fit = {float(n_eff), float(y_mean), float(s_yy)};
    return true;
}

// Hough transform of one half in window w: rho = (x - o.x) cos(theta) + (y - o.y) sin(theta),
// |rho| <= rho_max. A point at distance r from o in direction phi has rho = r cos(theta - phi), so
// it can only vote where theta is within asin(rho_max / r) of phi - 90 deg (the line through o and
// the point): a narrow window around a known vanishing point costs a few bins per point.
// Appends the refined lines of the strongest peaks.
void hough_half(const std::vector<MarkingPoint> &pts, const Half &h, const HoughWindow &w,
                const Acceptance &acc_rule, std::vector<LaneLine> &out) {
    const int min_votes = acc_rule.min_votes;
    const cv::Point2f o = w.origin;
    const float rho_max = w.rho_max, dt = w.theta_step_deg * kDeg, dr = w.rho_step_px;
    const int n_t = std::max(1, int(std::floor((h.theta_hi - h.theta_lo) / dt)) + 1);
    const int n_r = std::max(1, int(std::floor(2.f * rho_max / dr)) + 1);
    std::vector<float> cs(static_cast<size_t>(n_t)), sn(static_cast<size_t>(n_t));
    for (int t = 0; t < n_t; ++t) {
        cs[size_t(t)] = std::cos(h.theta_lo + t * dt);
        sn[size_t(t)] = std::sin(h.theta_lo + t * dt);
    }
    std::vector<int> acc(size_t(n_t) * size_t(n_r), 0);
    const float inv_dr = 1.f / dr;
    for (const auto &q : pts) {
        if (q.x < h.x_lo || q.x >= h.x_hi) continue;
        const float dx = q.x - o.x, dy = q.y - o.y;
        if (dy < 1.f) continue;  // at or above the vanishing point: not on the road
        const float r = std::sqrt(dx * dx + dy * dy);
        const float th0 = std::atan2(dy, dx) - float(M_PI / 2);
        const float d = rho_max >= r ? float(M_PI / 2) : std::asin(rho_max / r);
        const int t0 = std::max(0, int(std::ceil((th0 - d - h.theta_lo) / dt)));
        const int t1 = std::min(n_t - 1, int(std::floor((th0 + d - h.theta_lo) / dt)));
        for (int t = t0; t <= t1; ++t) {
            const int b = int((dx * cs[size_t(t)] + dy * sn[size_t(t)] + rho_max) * inv_dr + 0.5f);
            if (b >= 0 && b < n_r) ++acc[size_t(t) * size_t(n_r) + size_t(b)];
        }
    }

    // Local maxima (3x3) above the vote threshold, strongest first, non-maximum suppressed.
    std::vector<Peak> peaks;
    auto at = [&](int t, int r) {
        return (t < 0 || t >= n_t || r < 0 || r >= n_r) ? -1 : acc[size_t(t) * size_t(n_r) + size_t(r)];
    };
    for (int t = 0; t < n_t; ++t)
        for (int r = 0; r < n_r; ++r) {
            const int v = acc[size_t(t) * size_t(n_r) + size_t(r)];
            if (v < min_votes) continue;
            bool is_max = true;
            for (int a = -1; a <= 1 && is_max; ++a)
                for (int b = -1; b <= 1; ++b) {
                    const int u = at(t + a, r + b);
                    // ties: the first cell in scan order wins
                    if (u > v || (u == v && (a < 0 || (a == 0 && b < 0)))) { is_max = false; break; }
                }
            if (is_max) peaks.push_back({v, t, r});
        }
    std::sort(peaks.begin(), peaks.end(), [](const Peak &a, const Peak &b) { return a.votes > b.votes; });

    // Strongest peak first; each accepted line claims its points, so a weaker peak that shares
    // them (a marking plus a tail light, or a dash plus road texture) is judged on what is left.
    std::vector<Peak> kept;
    std::vector<char> claimed(pts.size(), 0);
    std::vector<size_t> support;
    for (const auto &pk : peaks) {
        if (int(kept.size()) >= w.max_peaks) break;
        bool near = false;
        for (const auto &k : kept) near |= std::abs(k.t - pk.t) <= 2 && std::abs(k.r - pk.r) <= 2;
        if (near) continue;
        kept.push_back(pk);

        // Peak -> image line: x(y) = o.x + (rho - (y - o.y) sin(theta)) / cos(theta).
        const float th = h.theta_lo + pk.t * dt, rho = pk.r * dr - rho_max;
        ImageLine l;
        l.y_ref = acc_rule.y_ref;
        l.k = -std::tan(th);
        l.x_ref = o.x + (rho - (l.y_ref - o.y) * std::sin(th)) / std::cos(th);
        LaneLine ll;
        if (!fit_line(pts, claimed, h, l, acc_rule.tol, w, ll, support)) continue;
        // Rejection: too little support, support bunched in a few rows (one vehicle), or an
        // implausible angle for this half (thesis).
        const float th_fit = -std::atan(ll.line.k);
        if (ll.votes < float(min_votes) || ll.span < acc_rule.min_span || th_fit < h.theta_lo - dt ||
            th_fit > h.theta_hi + dt)
            continue;
        for (size_t i : support) claimed[i] = 1;
        out.push_back(ll);
    }
}

} // namespace

HoughWindow wide_window(cv::Size size, const HorizonPrior &hp, const HoughLinesParams &p) {
    HoughWindow w;
    w.origin = {hp.vp_x, hp.row};
    w.rho_max = float(p.max_vp_offset_frac) * float(size.width) + hp.tol_px;
    w.theta_step_deg = 2.f * float(p.theta_step_deg);  // coarse: only the strong lines are needed here
    w.rho_step_px = 2.f * float(p.rho_step_px);
    w.max_peaks = std::max(1, p.max_peaks_per_half / 2);
    return w;
}

HoughWindow vp_window(cv::Point2f vp, bool tracked, cv::Size size, const HoughLinesParams &p) {
    HoughWindow w;
    w.origin = vp;
    w.rho_max = std::max(2.f * float(p.rho_step_px), float(p.vp_line_tol_frac) * float(size.width));
    w.theta_step_deg = float(p.theta_step_deg);
    w.rho_step_px = float(p.rho_step_px);
    w.max_peaks = p.max_peaks_per_half;
    w.anchor_weight = tracked ? float(p.vp_anchor_points) : 0.f;
    return w;
}

std::vector<LaneLine> hough_lane_lines(const std::vector<MarkingPoint> &pts, const ScanBand &band,
                                       cv::Size size, const CameraParams &cam, const HorizonPrior &hp,
                                       const HoughLinesParams &p, const HoughWindow &win) {
    if (size.width <= 0 || size.height <= 0) throw std::invalid_argument("hough_lane_lines: empty image size");
    std::vector<LaneLine> found;
    const int rows = band.rows();
    if (rows < 2 || pts.size() < 2) return found;

    const float w = float(size.width);
    const float overlap = 0.5f * float(p.max_vp_offset_frac) * w;
    const int min_votes = std::max(p.min_votes, int(std::ceil(p.min_votes_frac * rows)));
    const float tol = std::max(1.f, float(p.inlier_frac) * w);
    const float y_ref = float(band.y_bottom);
    const float a_max = float(p.max_angle_deg) * kDeg, a_cross = float(p.cross_angle_deg) * kDeg;

    // Left half: markings left of the camera lean "/" (k < 0, theta > 0); right half mirrored. The
    // halves split at the window's origin and overlap so lines near the split are seen whole.
    const Half left{-1e9f, win.origin.x + overlap, -a_cross, a_max};
    const Half right{win.origin.x - overlap, 1e9f, -a_max, a_cross};
    const Acceptance rule{min_votes, float(p.min_span_frac) * float(band.y_bottom - band.y_top), tol, y_ref};
    hough_half(pts, left, win, rule, found);
    hough_half(pts, right, win, rule, found);

    // Grouping by angle and lateral distance (thesis: many lines on one marking -> one line). The
    // strongest line of a group represents it; members closer than group_angle in angle and
    // group_sep_m at both ends of the band join it; the group's line is the vote-weighted mean.
    std::sort(found.begin(), found.end(), [](const LaneLine &a, const LaneLine &b) { return a.votes > b.votes; });
    const float y_top = float(band.y_top);
    const float sep_bottom = std::max(tol, float(p.group_sep_m) * px_per_m(cam, hp.row - hp.tol_px, y_ref));
    const float sep_top = std::max(tol, float(p.group_sep_m) * px_per_m(cam, hp.row - hp.tol_px, y_top));
    struct Group {
        LaneLine rep;
        double w = 0, xb = 0, xt = 0;
        float y_min = 1e9f, y_max = -1e9f;
    };
    std::vector<Group> groups;
    for (const auto &l : found) {
        Group *g = nullptr;
        for (auto &cand : groups) {
            const ImageLine &r = cand.rep.line;
            if (std::fabs(std::atan(r.k) - std::atan(l.line.k)) < float(p.group_angle_deg) * kDeg &&
                std::fabs(r.x_at(y_ref) - l.line.x_at(y_ref)) < sep_bottom &&
                std::fabs(r.x_at(y_top) - l.line.x_at(y_top)) < sep_top) {
                g = &cand;
                break;
            }
        }
        if (!g) {
            groups.push_back({l});
            g = &groups.back();
        }
        g->w += l.votes;
        g->xb += double(l.votes) * l.line.x_at(y_ref);
        g->xt += double(l.votes) * l.line.x_at(y_top);
        g->y_min = std::min(g->y_min, l.y_min);
        g->y_max = std::max(g->y_max, l.y_max);
    }

    std::vector<LaneLine> lines;
    for (const auto &g : groups) {
        LaneLine l = g.rep;  // votes: the strongest member's (members share their points)
        const float xb = float(g.xb / g.w), xt = float(g.xt / g.w);
        l.line.y_ref = y_ref;
        l.line.x_ref = xb;
        l.line.k = y_ref > y_top ? (xb - xt) / (y_ref - y_top) : l.line.k;
        l.y_min = g.y_min;
        l.y_max = g.y_max;
        lines.push_back(l);
    }
    std::sort(lines.begin(), lines.end(),
              [](const LaneLine &a, const LaneLine &b) { return a.line.x_ref < b.line.x_ref; });
    return lines;
}

} // namespace hw
