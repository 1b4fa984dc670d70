// camera.hpp - the forward camera: intrinsics and mounting, and the flat-road model.
//
// Axes as OpenCV: x right, y down, z forward. pitch_deg > 0 looks down, so the horizon of a level
// road is above the principal point: v_h = cy - fy * tan(pitch). Same convention as app/sim/camera.py.
#pragma once

#include "base/params.hpp"
#include "base/types.hpp"

#include <cmath>

namespace hw {

struct CameraParams {
    int width = 640;          // px, frame width the intrinsics refer to
    int height = 480;         // px
    double fx = 700.0;        // px, focal length along x
    double fy = 700.0;        // px, focal length along y
    double cx = 320.0;        // px, principal point
    double cy = 240.0;        // px
    double height_m = 1.3;    // m, camera height above the road
    double pitch_deg = 1.0;   // deg, positive looking down
    double yaw_deg = 0.0;     // deg, positive looking right
    double lateral_m = 0.0;   // m, camera offset right of the ego-lane centre line of the car
    double k1 = 0.0, k2 = 0.0, k3 = 0.0;  // radial lens distortion (OpenCV model, geometry/lens.hpp)
    double p1 = 0.0, p2 = 0.0;            // tangential lens distortion
    double hood_frac = 0.0;   // share of the image height at the bottom that is the car's own bonnet

    void bind(ParamMap &m) {
        m.add("width", width, 16, 8192, "px; frame width the intrinsics refer to; frames of another size are rejected");
        m.add("height", height, 16, 8192, "px; frame height the intrinsics refer to");
        m.add("fx", fx, 1.0, 100000.0, "px; focal length along x (calibration K[0][0])");
        m.add("fy", fy, 1.0, 100000.0, "px; focal length along y (calibration K[1][1])");
        m.add("cx", cx, -8192.0, 16384.0, "px; principal point column (K[0][2])");
        m.add("cy", cy, -8192.0, 16384.0, "px; principal point row (K[1][2])");
        m.add("height_m", height_m, 0.2, 5.0, "m; camera height above the road, sets the flat-road range scale");
        m.add("pitch_deg", pitch_deg, -30.0, 30.0, "deg; static pitch, positive looking down; the horizon row follows from it until lanes refine it");
        m.add("yaw_deg", yaw_deg, -30.0, 30.0, "deg; static yaw, positive looking right");
        m.add("lateral_m", lateral_m, -3.0, 3.0, "m; camera offset right of the car's centre line");
        m.add("k1", k1, -10.0, 10.0, "radial distortion r^2 coefficient (OpenCV model; `headway calibrate` measures it); "
              "image points are undistorted where they are mapped to the road");
        m.add("k2", k2, -100.0, 100.0, "radial distortion r^4 coefficient");
        m.add("p1", p1, -1.0, 1.0, "tangential distortion coefficient p1");
        m.add("p2", p2, -1.0, 1.0, "tangential distortion coefficient p2");
        m.add("k3", k3, -1000.0, 1000.0, "radial distortion r^6 coefficient");
        m.add("hood_frac", hood_frac, 0.0, 0.5,
              "share of the image height at the bottom taken by the car's own bonnet: those rows give no lane "
              "markings, shadows, road features or differences; e.g. 0.08 for TuSimple's clips; 0 = none");
    }

    bool has_distortion() const { return k1 != 0.0 || k2 != 0.0 || k3 != 0.0 || p1 != 0.0 || p2 != 0.0; }

    // First row of the car's bonnet in a frame `rows` high: the rows from it down show no road (`rows`: no bonnet).
    int hood_row(int rows) const { return rows - int(std::lround(hood_frac * rows)); }

    // Horizon row of a level road for the configured pitch.
    double horizon_row() const { return cy - fy * std::tan(pitch_deg * M_PI / 180.0); }
};

// The road's vanishing point for the road-motion parts: the lane model's, else the camera's horizon and yaw.
inline cv::Point2f road_vanishing_point(const LaneModel &lanes, const CameraParams &cam) {
    const cv::Point2f vp = lanes.vanishing_point;
    if (std::isfinite(vp.x) && std::isfinite(vp.y)) return vp;
    return {float(cam.cx - cam.fx * std::tan(cam.yaw_deg * M_PI / 180.0)), float(cam.horizon_row())};
}

} // namespace hw
