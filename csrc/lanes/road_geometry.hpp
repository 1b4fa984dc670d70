// road_geometry.hpp - the flat-road model as the lane stage uses it.
//
// A point of a level road at lateral offset X (m, right positive, from the camera) and range Z (m)
// images at
//     x = x_vp + fx * X / Z,        y = y_h + fy * h / Z
// (small pitch and yaw; x_vp, y_h the vanishing point of the road direction). Eliminating Z:
//     x - x_vp = (fx * X / (fy * h)) * (y - y_h)
// so every marking parallel to the road is an image line through the vanishing point whose slope
// k = dx/dy is proportional to its lateral offset: X = k * fy * h / fx. The lane stage classifies
// lines by that offset (ego lane, adjacent lanes, lane changes) and bounds its searches with it.
#pragma once

#include "geometry/camera.hpp"

#include <opencv2/core.hpp>

#include <algorithm>
#include <cmath>
#include <limits>

namespace hw {

// Where the lane stage expects the road's vanishing point before it has measured one, and how far
// off that expectation may be (pitch and yaw are only roughly known).
struct HorizonPrior {
    float row = 0.f;     // px, expected horizon row (camera pitch, or the tracked vanishing point)
    float vp_x = 0.f;    // px, expected column of the vanishing point (camera yaw, or tracked)
    float tol_px = 0.f;  // px, how far the true horizon row may be from `row`
};

// Prior from the camera alone: v_h = cy - fy tan(pitch); u_vp = cx - fx tan(yaw) (yaw right moves
// the road direction to the left of the optical axis); tolerance = fy tan(tol_deg).
inline HorizonPrior camera_horizon(const CameraParams &cam, double tol_deg) {
    HorizonPrior h;
    h.row = float(cam.horizon_row());
    h.vp_x = float(cam.cx - cam.fx * std::tan(cam.yaw_deg * M_PI / 180.0));
    h.tol_px = float(cam.fy * std::tan(tol_deg * M_PI / 180.0));
    return h;
}

// Lateral offset (m) of the marking whose image line has slope k = dx/dy.
inline float lateral_from_slope(const CameraParams &cam, float k) {
    return float(k * cam.fy * cam.height_m / cam.fx);
}

// Image slope dx/dy of a marking at lateral offset X (m).
inline float slope_from_lateral(const CameraParams &cam, float lateral_m) {
    return float(lateral_m * cam.fx / (cam.fy * cam.height_m));
}

// Pixels per metre across the road at image row y, for a horizon at row y_h (0 at or above it):
// fx / Z with Z = fy h / (y - y_h).
inline float px_per_m(const CameraParams &cam, float y_h, float y) {
    return float(std::max(0.0, cam.fx * (y - y_h) / (cam.fy * cam.height_m)));
}

// Image row of the road at range Z (m).
inline float row_at_range(const CameraParams &cam, float y_h, float range_m) {
    return float(y_h + cam.fy * cam.height_m / range_m);
}

// Range (m) of the road at image row y below the horizon y_h: Z = fy h / (y - y_h) (row_at_range's inverse).
inline float range_at_row(const CameraParams &cam, float y_h, float y) {
    return float(cam.fy * cam.height_m) / (y - y_h);
}

// A straight image line x(y) = x_ref + k (y - y_ref).
struct ImageLine {
    float x_ref = 0.f, y_ref = 0.f, k = 0.f;
    float x_at(float y) const { return x_ref + k * (y - y_ref); }
};

// Precision of a least-squares line fitted to points of equal noise sigma (a weighted anchor point
// counts with its weight): var(x at row y) = sigma^2 (1/n + (y - y_mean)^2 / s_yy). A long marking
// is known to a fraction of a pixel everywhere; a line through one short far dash is poorly known
// at the bottom of the image, far from its points.
struct LineFit {
    float n = 0.f;       // points (weights) in the fit
    float y_mean = 0.f;  // their mean row
    float s_yy = 0.f;    // sum of squared row deviations
    // sigma of x at row y in units of the point sigma (infinite for no fit).
    float rel_sigma_at(float y) const {
        if (n <= 0.f || s_yy <= 0.f) return std::numeric_limits<float>::infinity();
        return std::sqrt(1.f / n + (y - y_mean) * (y - y_mean) / s_yy);
    }
};

// The line n lanes to the side of `l` (n < 0: left) for a lane width of dk in slope, all lines
// meeting at the vanishing point vp: x'(y) = x(y) + n dk (y - vp.y).
inline ImageLine shifted_by_lanes(const ImageLine &l, float n, float dk, cv::Point2f vp) {
    ImageLine s = l;
    s.k = l.k + n * dk;
    s.x_ref = l.x_ref + n * dk * (l.y_ref - vp.y);
    return s;
}

// Intersection of two image lines; false when they are (nearly) parallel.
inline bool intersect(const ImageLine &a, const ImageLine &b, cv::Point2f &p) {
    const float dk = a.k - b.k;
    if (std::fabs(dk) < 1e-4f) return false;
    // a.x_ref + a.k (y - a.y_ref) = b.x_ref + b.k (y - b.y_ref)
    const float y = (b.x_ref - b.k * b.y_ref - a.x_ref + a.k * a.y_ref) / dk;
    p = {a.x_at(y), y};
    return true;
}

// Perpendicular distance of point p from the line.
inline float distance(const ImageLine &l, cv::Point2f p) {
    return std::fabs(p.x - l.x_at(p.y)) / std::sqrt(1.f + l.k * l.k);
}

} // namespace hw
