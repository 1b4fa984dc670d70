// road_scene.hpp - test scenes on the flat road: the ego lane as a camera sees it.
#pragma once

#include "base/types.hpp"
#include "geometry/flat_road.hpp"

#include <cmath>

namespace hw_test {

// The ego lane `width_m` wide, the car on its centre line, as `cam` sees it and measured this frame (valid,
// certain, both boundaries observed): straight boundaries through the road points near_m and far_m ahead.
inline hw::LaneModel ego_lane(const hw::CameraParams &cam, double width_m = 3.6, double near_m = 6.0,
                              double far_m = 60.0) {
    const double vh = cam.horizon_row();
    auto boundary = [&](double x) {
        hw::LaneBoundary b;
        b.valid = b.observed = true;
        b.bottom = cv::Point2f(hw::project_road_point(cam, x, near_m, vh));
        b.top = cv::Point2f(hw::project_road_point(cam, x, far_m, vh));
        return b;
    };
    hw::LaneModel m;
    m.ego_left = boundary(-width_m / 2);
    m.ego_right = boundary(width_m / 2);
    m.valid = m.certain = true;
    m.vanishing_point = {float(cam.cx - cam.fx * std::tan(cam.yaw_deg * M_PI / 180.0)), float(vh)};
    return m;
}

} // namespace hw_test
