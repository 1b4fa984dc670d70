// vehicle_shape.hpp - the size and shape of the vehicles Headway detects: configuration section "vehicle_shape".
//
// The prior that every detector and tracker assumes of a vehicle, written once here:
//  - width_m: the nominal rear width; with the lane width it gives the expected width in pixels at each row
//    (the road prior of the shadow, cascade and proposals detectors, the verification, the Kalman tracker's
//    px <-> m conversions) and the parallax detector's expected region width;
//  - max_height_m: the tallest vehicle above the road (the cascade's scan rows, the parallax detector's top
//    search for a vehicle cut by the image's side);
//  - aspect: a car's rear, height / width, the height the verification gives a box whose top it cannot find;
//  - top_min_aspect: a measured top lower than this many widths is not trusted (a car's upper sides fade into the
//    rear window), in the verification and the parallax detector alike;
//  - max_aspect: the tallest box, height / width (a truck's rear): the verification's top search and the parallax
//    detector's region height stop there.
// The configuration hands the one section to every part that holds a copy (their `shape` member, taken by
// their section's `share`), so no part has a key of its own for these. The name is not "vehicle": the
// supervisor's section of that name holds the ego car's own CAN inputs.
// In geometry/ (below detect and track) so that every part can include it.
#pragma once

#include "base/params.hpp"

namespace hw {

struct VehicleShapeParams {
    double width_m = 1.8;         // m; nominal rear width of a vehicle (passenger car)
    double max_height_m = 4.5;    // m; tallest vehicle above the road (a truck)
    double aspect = 0.8;          // box height / width of a car's rear: the height when no top is found (thesis: 1)
    double top_min_aspect = 0.9;  // a top found lower than this many widths is not trusted
    double max_aspect = 1.6;      // tallest box, height / width (a truck's rear)

    void bind(ParamMap &m) {
        m.add("width_m", width_m, 0.5, 5.0,
              "m; nominal rear width of a vehicle; with the lane width it gives the expected width in pixels at "
              "each row for the detectors and trackers");
        m.add("max_height_m", max_height_m, 0.5, 10.0,
              "m; tallest vehicle above the road (4.5 m: a truck); bounds the cascade's scan rows and the top "
              "search of a vehicle cut by the image's side");
        m.add("aspect", aspect, 0.2, 3.0,
              "box height / width of a vehicle whose top is not found; the thesis used 1 for every vehicle, rear "
              "views of cars measure about 0.8");
        m.add("top_min_aspect", top_min_aspect, 0.1, 5.0,
              "height / width; a top found lower than this is not trusted: 0.9 leaves cars (whose upper sides "
              "fade into the rear window) to the fixed aspect or their region's height, and measures trucks");
        m.add("max_aspect", max_aspect, 0.2, 5.0,
              "height / width of the tallest vehicle box (a truck's rear is about 1.6); the top search and the "
              "parallax detector's region height stop there");
    }
};

} // namespace hw
