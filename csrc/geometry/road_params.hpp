// road_params.hpp - the road's physical dimensions that several stages assume: configuration section "road".
//
// Written once here and read by the lanes (expected lane width), the detectors' road prior (expected vehicle width
// at a row: w(y) = lane_width_px(y) * vehicle_shape.width_m / lane_width_m; the vehicle's own size is in
// geometry/vehicle_shape.hpp), self-calibration (camera height from the lane width: h = fx W cos(theta) / (fy a))
// and lead selection (the ego corridor without lanes, and which lane models are believed). The configuration (core/config.cpp) hands the one section to
// every unit that holds a copy (their `road` member), so no unit has a key of its own for these.
// In geometry/ (below lanes, detect, track and fcw) so that every one of them can include it.
#pragma once

#include "base/params.hpp"

namespace hw {

struct RoadParams {
    double lane_width_m = 3.6;      // m; nominal lane width (motorway)
    double min_lane_width_m = 2.5;  // m; narrowest ego lane believed on the flat road
    double max_lane_width_m = 4.0;  // m; widest ego lane believed

    void bind(ParamMap &m) {
        m.add("lane_width_m", lane_width_m, 2.0, 5.0,
              "m; nominal lane width: the lane model's expected width, its pixel-to-metre scale, the ego corridor "
              "without lanes, and self-calibration's height reference (docs/calibration.md)");
        m.add("min_lane_width_m", min_lane_width_m, 1.0, 10.0,
              "m; a lane model whose ego lane is narrower than this at its lower end (flat road, current horizon) "
              "is uncertain: lines found on vehicles or seams of an unmarked road; lead selection then uses the "
              "path from the yaw rate");
        m.add("max_lane_width_m", max_lane_width_m, 1.0, 20.0,
              "m; nor one wider than this; lanes are built 3.0-3.75 m wide, and lines on an unmarked road (vehicle "
              "sides, seams) made a 4.2-4.8 m \"lane\" holding the adjacent cars in congestion_no_markings");
    }
};

} // namespace hw
