// vehicle_height.hpp - a tracked vehicle's height from its detections: a truck keeps its measured height.
//
// The trackers measure a vehicle's bottom and sides; its height comes from the detections, each a new estimate of
// the aspect (height / width) blended in with the tracker's gain. A detection's top is either measured (the
// verification found how far up both sides reach, cues/vehicle_top.hpp) or guessed: no top cue, and the
// verification gives a car's aspect (vehicle_shape.aspect, 0.8). For a car the guess is about right, and measured
// tops are noisy (a near car's top search sometimes climbs onto what stands behind it: 1.0-1.6 widths on
// successive runs for a car of 0.8, synthetic dense_traffic). For a truck (1.4-1.6 widths) the guess halves its box,
// and a track whose box the guesses keep halving loses the truck (synthetic cut_in; docs/tracking.md).
// So: a vehicle whose measured tops said taller than tall_aspect tall_hits times in a row (guessed tops skipped,
// and boxes the image's side cuts: a car half out of the image is as tall as ever and half as wide) is tall; a tall vehicle's aspect takes only measured tops, and it is matched to a guessed detection as if that
// detection were as tall as it (same bottom and sides). Configuration section "vehicle_height", handed to both
// trackers that keep a box height (kalman, phd).
#pragma once

#include "base/params.hpp"
#include "cues/hypothesis.hpp"
#include "geometry/vehicle_shape.hpp"

#include <opencv2/core.hpp>

namespace hw {

struct VehicleHeightParams {
    double tall_aspect = 1.2;  // height / width above which a vehicle is a truck or a bus (no car is: 0.8-1.0)
    int tall_hits = 2;         // measured tops in a row (guessed ones skipped) that make a vehicle tall

    void bind(ParamMap &m) {
        m.add("tall_aspect", tall_aspect, 0.5, 10.0,
              "height / width above which a vehicle is a truck or bus: a tracked one that tall keeps its measured "
              "height against guessed detection heights; 10 = never (docs/tracking.md)");
        m.add("tall_hits", tall_hits, 1, 100,
              "detections in a row whose measured top says taller than tall_aspect (guessed tops skipped) before a "
              "vehicle is taken as tall: a near car's top search sometimes climbs onto what stands behind it, once");
    }
};

// The height a tracker keeps for one vehicle.
struct VehicleHeight {
    double aspect = VehicleShapeParams{}.aspect;  // box height / width (start: the first detection's)
    int tall_run = 0;     // detections in a row whose measured top made it taller than tall_aspect

    // From the vehicle's first detection, in an image `cols` wide.
    void start(const Hypothesis &d, int cols, const VehicleHeightParams &p);
    // One more detection of the vehicle, blended in with `gain` (0..1) unless it only guesses a tall vehicle's height.
    void take(const Hypothesis &d, int cols, double gain, const VehicleHeightParams &p);
    bool tall(const VehicleHeightParams &p) const { return tall_run >= p.tall_hits; }
    // The detection's box as compared with the vehicle's box `vb` when matching: a guessed height as tall as vb.
    cv::Rect2f compared_box(const Hypothesis &d, const cv::Rect2f &vb, const VehicleHeightParams &p) const;
};

} // namespace hw
