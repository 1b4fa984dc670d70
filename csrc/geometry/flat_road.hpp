// flat_road.hpp - image rows and columns to road coordinates for a pinhole camera over a flat road.
//
// Camera axes as OpenCV (x right, y down, z forward), pitched down by theta and yawed right by psi,
// height h above the road. For a pixel (u, v) the normalised ray is (x_n, y_n, 1) with
// x_n = (u - cx)/fx, y_n = (v - cy)/fy. Undoing the pitch, the ray meets the road where its downward
// component equals h:
//     s = h / (y_n cos(theta) + sin(theta))            (ray scale; > 0 only below the horizon)
//     Z_c = s (cos(theta) - y_n sin(theta)),  X_c = s x_n       (level camera frame)
// and undoing the yaw: Z = Z_c cos(psi) - X_c sin(psi), X = X_c cos(psi) + Z_c sin(psi) + lateral.
// The horizon row (y_n cos + sin = 0) is v_h = cy - fy tan(theta). Near the axis the familiar
// Z ~= fy h / (v - v_h) holds, so dZ/dv ~= -Z^2 / (fy h): one row of error costs Z^2/(fy h) metres.
#pragma once

#include "geometry/camera.hpp"
#include "geometry/lens.hpp"

#include <opencv2/core/types.hpp>

#include <cmath>

namespace hw {

struct RoadPoint {
    double x_m = NAN;  // lateral, right positive, from the car's centre line
    double z_m = NAN;  // forward, from the camera
    bool valid() const { return std::isfinite(z_m) && z_m > 0; }
};

// Pitch (rad) that puts the horizon at row `horizon_row`.
inline double pitch_of_horizon(const CameraParams &cam, double horizon_row) {
    return std::atan((cam.cy - horizon_row) / cam.fy);
}

// Road point seen at pixel (u, v) of the (distorted) image with the camera pitched so that the horizon
// is at `horizon_row` (a row of the undistorted image; the same row near the image centre).
inline RoadPoint road_point(const CameraParams &cam, double u, double v, double horizon_row) {
    const double th = pitch_of_horizon(cam, horizon_row);
    const double psi = cam.yaw_deg * M_PI / 180.0;
    const ImagePoint p = undistort_pixel(cam, u, v);  // identity without distortion keys
    const double xn = (p.u - cam.cx) / cam.fx, yn = (p.v - cam.cy) / cam.fy;
    const double den = yn * std::cos(th) + std::sin(th);
    if (den <= 1e-9) return {};  // at or above the horizon: the ray never meets the road
    const double s = cam.height_m / den;
    const double zc = s * (std::cos(th) - yn * std::sin(th)), xc = s * xn;
    return {xc * std::cos(psi) + zc * std::sin(psi) + cam.lateral_m, zc * std::cos(psi) - xc * std::sin(psi)};
}

// Pixel (u, v) where the point `above_m` above the road at (x_m lateral, z_m forward) is seen, with the
// horizon at `horizon_row`: the inverse of road_point (above_m = 0). Level frame -> camera: undo the
// lateral offset and yaw (x_c = (X - lat) cos(psi) - Z sin(psi), z_c = (X - lat) sin(psi) + Z cos(psi)),
// then the pitch (y = (h - above) cos(theta) - z_c sin(theta), z = (h - above) sin(theta) + z_c cos(theta)),
// u = cx + fx x_c / z, v = cy + fy y / z. NaN when the point is behind the camera.
inline cv::Point2d project_road_point(const CameraParams &cam, double x_m, double z_m, double horizon_row,
                                      double above_m = 0.0) {
    const double th = pitch_of_horizon(cam, horizon_row);
    const double psi = cam.yaw_deg * M_PI / 180.0;
    const double xl = x_m - cam.lateral_m;
    const double xc = xl * std::cos(psi) - z_m * std::sin(psi), zl = xl * std::sin(psi) + z_m * std::cos(psi);
    const double yl = cam.height_m - above_m;
    const double y = yl * std::cos(th) - zl * std::sin(th), z = yl * std::sin(th) + zl * std::cos(th);
    if (!(z > 1e-6)) return {NAN, NAN};
    return {cam.cx + cam.fx * xc / z, cam.cy + cam.fy * y / z};
}

// 1-sigma range uncertainty from a 1-sigma uncertainty of the contact row.
inline double range_sigma(const CameraParams &cam, double z_m, double row_sigma_px) {
    return z_m * z_m / (cam.fy * cam.height_m) * row_sigma_px;
}

} // namespace hw
