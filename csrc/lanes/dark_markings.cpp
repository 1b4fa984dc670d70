#include "lanes/dark_markings.hpp"

#include "lanes/road_gray.hpp"

#include <algorithm>
#include <cmath>

namespace hw {

namespace {

// One dark bar as a lane-spacing factor: the bar lies s_j ego-lane widths out from the ego boundary of its side,
// and belongs to a line of factor s when |s_j - s| <= tol_j (the corridor in lane widths at its row).
struct DarkBar {
    float s = 0.f, tol = 0.f, width = 0.f;  // width: the ego lane's width in px at the bar's row
    int row = 0;
};

// The combination (1 + s) near - s far of two boundaries with the same rows and curve term: the line s lane
// widths beyond `near` on the side away from `far` (lane_curve.hpp: every term of curve_x is linear in them).
LaneBoundary beyond(const LaneBoundary &near, const LaneBoundary &far, float s) {
    LaneBoundary b = near;
    b.bottom.x = (1.f + s) * near.bottom.x - s * far.bottom.x;
    b.top.x = (1.f + s) * near.top.x - s * far.top.x;
    b.bend = (1.f + s) * near.bend - s * far.bend;
    b.valid = b.observed = true;
    return b;
}

} // namespace

void add_dark_adjacent(const cv::Mat &gray, const ScanBand &band, const CameraParams &cam, const HorizonPrior &hp,
                       const MarkingFilterParams &filter, const DarkLineParams &p, LaneModel &m) {
    if (!p.enabled || !m.valid || (m.adj_left.valid && m.adj_right.valid)) return;
    const LaneBoundary &L = m.ego_left, &R = m.ego_right;
    if (L.bottom.y != R.bottom.y || L.top.y != R.top.y || L.curve != R.curve ||
        !(L.curve_row == R.curve_row || (std::isnan(L.curve_row) && std::isnan(R.curve_row))))
        return;  // not one road's pair (the combination below needs the same rows and curve term)
    // Dark bars of a marking's width: the marking filter on the inverted image (its bars and its short bars).
    cv::Mat inv = 255 - gray;
    std::vector<MarkingPoint> pts, shorts;
    find_marking_points(inv, band, cam, hp, filter, pts, &shorts, true);
    pts.insert(pts.end(), shorts.begin(), shorts.end());
    // On the road: both sides of the bar as bright as the ego lane's road on its row (within road_frac either
    // way; its median sampled every 2 px between the ego boundaries): a vehicle's tyres, trim or gaps between
    // its parts are dark bars too, between a body brighter or darker than the road.
    EgoRoadGray road(gray, L, R);
    auto on_road = [&](const MarkingPoint &q) {
        if (p.road_frac <= 0.0) return true;
        const int y = int(std::lround(q.y)), half = int(std::ceil(0.5f * q.width)) + 2;
        const int xa = int(std::lround(q.x)) - half, xb = int(std::lround(q.x)) + half;
        const int median = road.at(y);
        if (median < 0 || xa < 0 || xb >= gray.cols) return false;
        const float lo = float(p.road_frac) * float(median), hi = float(median) / float(p.road_frac);
        const float a = gray.at<uint8_t>(y, xa), b = gray.at<uint8_t>(y, xb);
        return std::min(a, b) >= lo && std::max(a, b) <= hi;
    };
    for (int side = -1; side <= 1; side += 2) {
        LaneBoundary &adj = side < 0 ? m.adj_left : m.adj_right;
        if (adj.valid) continue;
        const LaneBoundary &near = side < 0 ? L : R, &far = side < 0 ? R : L;
        std::vector<DarkBar> bars;
        for (const auto &q : pts) {
            if (q.y < L.top.y || !on_road(q)) continue;
            const float xn = near.curve_x(q.y), w = R.curve_x(q.y) - L.curve_x(q.y);
            if (!(w > 1.f) || !std::isfinite(xn)) continue;
            DarkBar b;
            b.s = float(side) * (q.x - xn) / w;
            b.width = w;
            b.tol = std::max(float(p.corridor_lanes), 1.5f / w);  // never under 1.5 px: a bar centre rounds to a pixel
            b.row = int(std::lround(q.y));
            if (std::fabs(b.s - 1.f) <= float(p.width_tol) + b.tol) bars.push_back(b);
        }
        // The factor with the most rows holding a bar on its line (steps of 0.01 lane widths).
        auto rows_at = [&](float s, std::vector<const DarkBar *> *on) {
            std::vector<int> rows;
            for (const auto &b : bars)
                if (std::fabs(b.s - s) <= b.tol) {
                    rows.push_back(b.row);
                    if (on) on->push_back(&b);
                }
            std::sort(rows.begin(), rows.end());
            return int(std::unique(rows.begin(), rows.end()) - rows.begin());
        };
        float best_s = 1.f;
        int best = 0;
        for (float s = 1.f - float(p.width_tol); s <= 1.f + float(p.width_tol) + 1e-4f; s += 0.01f) {
            const int n = rows_at(s, nullptr);
            if (n > best) { best = n; best_s = s; }
        }
        if (best < p.min_rows) continue;
        // The line through its bars: least squares in px, each bar (s_j - s) w_j px off.
        std::vector<const DarkBar *> on;
        rows_at(best_s, &on);
        double num = 0.0, den = 0.0;
        for (const DarkBar *b : on) {
            num += double(b->width) * b->width * b->s;
            den += double(b->width) * b->width;
        }
        const float s = den > 0.0 ? float(num / den) : best_s;
        adj = beyond(near, far, s);
    }
}

} // namespace hw
