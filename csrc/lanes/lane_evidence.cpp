#include "lanes/lane_evidence.hpp"

#include "lanes/road_geometry.hpp"

#include <algorithm>
#include <cmath>

namespace hw {

namespace {

// Does marking point q count as paint on boundary b? Within the tolerance of b's curve, no wider than a marking at
// its row on the model's road (the filter's width test allows for any horizon within the prior's tolerance and for
// slant: the gap between two dark vehicles, or a vehicle and the barrier's shadow, passes it as a "bar" 1-5 m wide),
// and outside every box of `hidden` (a vehicle hides the road: a bright bar there is the vehicle).
//   tolerance = max(min_tolerance_px, tolerance_m * ppm(y)),  width <= 1.2 max_width_m * ppm(y) + 2 px (blur),
//   ppm(y) = fx (y - y_h) / (fy h), the flat road's pixels per metre across the road at row y.
bool is_paint_on(const MarkingPoint &q, const LaneBoundary &b, const std::vector<cv::Rect2f> &hidden, float y_h,
                 const CameraParams &cam, const LaneEvidenceParams &p) {
    const float ppm = px_per_m(cam, y_h, q.y);
    const float tol = std::max(float(p.min_tolerance_px), float(p.tolerance_m) * ppm);
    if (!(std::fabs(q.x - b.curve_x(q.y)) <= tol)) return false;
    if (p.max_width_m > 0.0 && q.width > 1.2f * float(p.max_width_m) * ppm + 2.f) return false;
    return std::none_of(hidden.begin(), hidden.end(), [&](const cv::Rect2f &r) { return r.contains({q.x, q.y}); });
}

} // namespace

float boundary_support(const LaneBoundary &b, const std::vector<MarkingPoint> &pts,
                       const std::vector<cv::Rect2f> &hidden, float y_h, float y_near, const CameraParams &cam,
                       const LaneEvidenceParams &p, bool visible_only) {
    if (!b.valid || !std::isfinite(y_h) || p.bins < 1 || !(y_near > y_h + 1.f)) return 0.f;
    // The bins split [Z_near, Z_far] of the flat road in log range.
    const float z_near = range_at_row(cam, y_h, y_near);
    const float z_far = float(p.far_m);
    if (!(z_far > z_near)) return 0.f;
    const float log_span = std::log(z_far / z_near);
    const float y_far = row_at_range(cam, y_h, z_far);
    std::vector<char> hit(size_t(p.bins), 0);
    for (const auto &q : pts) {
        if (q.y < y_far || q.y > y_near || !is_paint_on(q, b, hidden, y_h, cam, p)) continue;
        const float z = range_at_row(cam, y_h, q.y);  // q.y >= y_far > y_h
        const int bin = std::clamp(int(float(p.bins) * std::log(z / z_near) / log_span), 0, p.bins - 1);
        hit[size_t(bin)] = 1;
    }
    // visible_only: share of the bins where the boundary is in the image at all (a line two lanes out
    // leaves the image near the car), a bin counting when the boundary's column at its middle range is
    // inside the frame. Else of all bins: an ego boundary is in view near the car.
    int n = 0, visible = 0;
    for (int k = 0; k < p.bins; ++k) {
        const float z_mid = z_near * std::exp(log_span * (float(k) + 0.5f) / float(p.bins));
        const float x = b.curve_x(row_at_range(cam, y_h, z_mid));
        if (!visible_only || (x >= 0.f && x < float(cam.width))) {
            ++visible;
            n += hit[size_t(k)];
        }
    }
    return visible > 0 ? float(n) / float(visible) : 0.f;
}

float boundary_row_coverage(const LaneBoundary &b, const std::vector<MarkingPoint> &pts,
                            const std::vector<cv::Rect2f> &hidden, float y_h, const ScanBand &band,
                            const CameraParams &cam, const LaneEvidenceParams &p) {
    if (!b.valid || !std::isfinite(y_h) || band.rows() < 1) return 0.f;
    // the scanned rows y_top + i step nearer than far_m, where the boundary is inside the image
    const float y_far = row_at_range(cam, y_h, float(p.far_m));
    const int n_rows = band.rows();
    std::vector<char> hit(size_t(n_rows), 0), counted(size_t(n_rows), 0);
    for (int i = 0; i < n_rows; ++i) {
        const float y = float(band.y_top + i * band.step), x = b.curve_x(y);
        counted[size_t(i)] = y >= y_far && x >= 0.f && x < float(cam.width);
    }
    for (const auto &q : pts) {
        const int i = int(std::lround((q.y - float(band.y_top)) / float(band.step)));
        if (i < 0 || i >= n_rows || !counted[size_t(i)] || !is_paint_on(q, b, hidden, y_h, cam, p)) continue;
        hit[size_t(i)] = 1;
    }
    const long n = std::count(counted.begin(), counted.end(), char(1));
    return n > 0 ? float(std::count(hit.begin(), hit.end(), char(1))) / float(n) : 0.f;
}

void drop_unsupported_outer(LaneModel &m, const std::vector<MarkingPoint> &pts, const std::vector<cv::Rect2f> &hidden,
                            float y_h, float y_near, const CameraParams &cam, const LaneEvidenceParams &p) {
    const float need = float(p.min_outer_support);
    // Every bar counts here, whatever its width: far out a line's few points in the counted range include bars the
    // width test rejects (0531/...694's labelled line two lanes out: 0.7-2.8 m at 25 m), and outer lines are only
    // reported, never believed by the detectors or the lead selection.
    LaneEvidenceParams any_width = p;
    any_width.max_width_m = 0.0;
    for (LaneBoundary *b : {&m.out_left, &m.out_right})
        if (b->valid && boundary_support(*b, pts, hidden, y_h, y_near, cam, any_width, true) < need) *b = LaneBoundary();
}

void drop_beyond_solid_edges(LaneModel &m, const std::vector<MarkingPoint> &pts, const std::vector<cv::Rect2f> &hidden,
                             float y_h, const ScanBand &band, const CameraParams &cam, const LaneEvidenceParams &p) {
    if (p.solid_min_rows <= 0.0) return;
    auto solid = [&](const LaneBoundary &b) {
        return boundary_row_coverage(b, pts, hidden, y_h, band, cam, p) >= float(p.solid_min_rows);
    };
    if (solid(m.ego_left)) m.adj_left = m.out_left = LaneBoundary();
    if (solid(m.ego_right)) m.adj_right = m.out_right = LaneBoundary();
}

} // namespace hw
