#include "lanes/lane_evidence.hpp"

#include "lanes/road_geometry.hpp"

#include <algorithm>
#include <cmath>

namespace hw {

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
        if (q.y < y_far || q.y > y_near) continue;
        const float tol = std::max(float(p.min_tolerance_px), float(p.tolerance_m) * px_per_m(cam, y_h, q.y));
        if (!(std::fabs(q.x - b.curve_x(q.y)) <= tol)) continue;
        if (std::any_of(hidden.begin(), hidden.end(), [&](const cv::Rect2f &r) { return r.contains({q.x, q.y}); }))
            continue;
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
        if (i < 0 || i >= n_rows || !counted[size_t(i)]) continue;
        const float tol = std::max(float(p.min_tolerance_px), float(p.tolerance_m) * px_per_m(cam, y_h, q.y));
        if (!(std::fabs(q.x - b.curve_x(q.y)) <= tol)) continue;
        if (std::any_of(hidden.begin(), hidden.end(), [&](const cv::Rect2f &r) { return r.contains({q.x, q.y}); }))
            continue;
        hit[size_t(i)] = 1;
    }
    const long n = std::count(counted.begin(), counted.end(), char(1));
    return n > 0 ? float(std::count(hit.begin(), hit.end(), char(1))) / float(n) : 0.f;
}

void drop_unsupported_outer(LaneModel &m, const std::vector<MarkingPoint> &pts, const std::vector<cv::Rect2f> &hidden,
                            float y_h, float y_near, const CameraParams &cam, const LaneEvidenceParams &p) {
    const float need = float(p.min_outer_support);
    for (LaneBoundary *b : {&m.out_left, &m.out_right})
        if (b->valid && boundary_support(*b, pts, hidden, y_h, y_near, cam, p, true) < need) *b = LaneBoundary();
}

} // namespace hw
