// road_prior.hpp - where the shadow detector looks, and how wide a vehicle is at each image row.
//
// Two sources, the lane model first and the flat-road camera model as fallback:
//  - lanes valid: the scan area is the lane stage's road polygon, widened to at least the ego lane
//    plus `adjacent_lanes` lane widths each side (so vehicles in the adjacent lanes are always
//    scanned); expected vehicle width w(y) = lane_width_px(y) * shape.width_m / road.lane_width_m
//    (thesis 2.4.2.1: "the width of a vehicle in an image is related to the width of the lane").
//  - lanes invalid: a trapezoid of half-width road_half_width_m around the camera's ego-lane
//    centre line, and w(y) from the pinhole model of a level road:
//        Z(y) = fy * h / (y - y_h),  w(y) = fx * W / Z(y) = (fx / fy) * W * (y - y_h) / h.
// The horizon row y_h is the lanes' vanishing point when valid, else cy - fy * tan(pitch).
#pragma once

#include "base/params.hpp"
#include "base/sections.hpp"
#include "base/types.hpp"
#include "geometry/camera.hpp"
#include "geometry/road_params.hpp"
#include "geometry/vehicle_shape.hpp"

#include <vector>

namespace hw {

struct RoadPriorParams {
    RoadParams road;                  // section "road" (lane_width_m), taken by share
    VehicleShapeParams shape;         // section "vehicle_shape" (width_m), taken by share
    double road_half_width_m = 9.0;   // m; fallback scan half-width around the ego-lane centre
    int adjacent_lanes = 2;           // lanes scanned each side of the ego lane at least
    double max_range_m = 120.0;       // m; the scan starts at the row of this range below the horizon

    void share(const SectionLookup &c) {  // the lane width and the vehicle width
        road = c.get<RoadParams>("road");
        shape = c.get<VehicleShapeParams>("vehicle_shape");
    }
    void bind(ParamMap &m) {
        m.add("road_half_width_m", road_half_width_m, 1.0, 50.0,
              "m; without a valid lane model the detector scans this far either side of the ego-lane "
              "centre; 9 m covers the ego lane and two lanes each side");
        m.add("adjacent_lanes", adjacent_lanes, 0, 4,
              "lanes; with a valid lane model the scan covers at least this many lanes beside the ego "
              "lane, so vehicles in adjacent lanes are found even if the road polygon is narrower");
        m.add("max_range_m", max_range_m, 10.0, 1000.0,
              "m; the scan starts at the row of this range on a flat road; farther vehicles are a few "
              "pixels wide and cannot be verified anyway");
    }
};

// The scan area as one interval per row, and the expected vehicle width per row.
struct RoadPrior {
    float horizon_row = kNaN;
    int y_top = 0, y_bottom = 0;   // scanned rows [y_top, y_bottom)
    bool from_lanes = false;       // lane model used (else the camera fallback)
    std::vector<int> x_left, x_right;     // per row (index y - y_top), inclusive; empty if left > right
    std::vector<float> width_px;          // expected vehicle width per row

    bool empty() const { return y_bottom <= y_top; }
    bool contains_row(int y) const { return y >= y_top && y < y_bottom; }
    float expected_width(int y) const { return width_px[size_t(y - y_top)]; }
    int left(int y) const { return x_left[size_t(y - y_top)]; }
    int right(int y) const { return x_right[size_t(y - y_top)]; }
};

// Builds the prior for an image of `size`. The camera is scaled to the image width if its
// configured size differs (Pipeline::detect_image on images of another resolution).
RoadPrior make_road_prior(cv::Size size, const LaneModel &lanes, const CameraParams &cam,
                          const RoadPriorParams &p);

// Horizon row for an image of `size`: the lane model's vanishing point when valid, else the camera's.
float horizon_row(cv::Size size, const LaneModel &lanes, const CameraParams &cam);

// Vanishing point of the road direction: the lane model's when valid, else (cx - fx tan(yaw), horizon).
cv::Point2f vanishing_point(cv::Size size, const LaneModel &lanes, const CameraParams &cam);

// Expected vehicle width in pixels for a box whose bottom is at row y (lane model or camera).
float expected_vehicle_width(float y, cv::Size size, const LaneModel &lanes, const CameraParams &cam,
                             const RoadPriorParams &p);

} // namespace hw
