// lens.hpp - lens distortion of image points (OpenCV's model), undone point by point.
//
// Normalised ideal coordinates (x, y) = ((u - cx)/fx, (v - cy)/fy) are bent by the lens into
//     x_d = x (1 + k1 r^2 + k2 r^4 + k3 r^6) + 2 p1 x y + p2 (r^2 + 2 x^2)
//     y_d = y (1 + k1 r^2 + k2 r^4 + k3 r^6) + p1 (r^2 + 2 y^2) + 2 p2 x y,    r^2 = x^2 + y^2.
// The inverse has no closed form; like cv::undistortPoints we iterate
//     (x, y) <- ((x_d, y_d) - tangential(x, y)) / radial(x, y)
// from (x, y) = (x_d, y_d), which converges in a few steps for the distortion of real lenses
// (Udacity's camera_cal lens: < 0.01 px after 8 steps at the image corners, tests/test_calibrate.py).
// Only the points that are mapped to the road are undistorted (a few per vehicle), never whole images.
#pragma once

#include "geometry/camera.hpp"

namespace hw {

struct ImagePoint {
    double u = 0, v = 0;  // px
};

// The pixel (u, v) would have been seen at by a distortion-free camera with the same fx, fy, cx, cy.
inline ImagePoint undistort_pixel(const CameraParams &cam, double u, double v) {
    if (!cam.has_distortion()) return {u, v};
    const double xd = (u - cam.cx) / cam.fx, yd = (v - cam.cy) / cam.fy;
    double x = xd, y = yd;
    for (int i = 0; i < 8; ++i) {
        const double r2 = x * x + y * y;
        const double radial = 1.0 + r2 * (cam.k1 + r2 * (cam.k2 + r2 * cam.k3));
        const double dx = 2.0 * cam.p1 * x * y + cam.p2 * (r2 + 2.0 * x * x);
        const double dy = cam.p1 * (r2 + 2.0 * y * y) + 2.0 * cam.p2 * x * y;
        x = (xd - dx) / radial;
        y = (yd - dy) / radial;
    }
    return {cam.cx + cam.fx * x, cam.cy + cam.fy * y};
}

} // namespace hw
