// hypothesis.hpp - what a detector hands a tracker: the frame with the road's context, and vehicle hypotheses.
//
// Below both the detector parts (detect/) and the tracker parts (track/), which never include each other: a
// tracker asks for a full detection through the detection stage's interface (cues/detection_stage.hpp).
#pragma once

#include "base/types.hpp"
#include "geometry/camera.hpp"

namespace hw {

// The frame and what is known about the road in it.
struct RoadContext {
    const cv::Mat &gray;                 // CV_8UC1 of the camera's configured size
    double t_s;                          // capture time, s
    const LaneModel &lanes;              // this frame's lane model (may be invalid)
    const CameraParams &camera;
    const RoadMotionFrame *motion;       // the road-motion stage's output; null when no part needs it
    bool single_image = false;           // one image alone (Pipeline::detect_image): no tracker follows
};

// One vehicle hypothesis.
struct Hypothesis {
    cv::Rect2f box;          // px; the vehicle's rear face
    cv::Point2f foot;        // px; the point the detector measured it at (bottom centre of its region)
    float score = 0.f;       // 0..1; how sure the detector is (comparable across detectors)
    float strength = 0.f;    // the detector's own measure (edge excess, mean |difference|), orders hypotheses of one source
    const char *source = ""; // the registry name of the detector that made it
    float road_gray = kNaN;  // gray level of the road where the detector measured the bottom edge (shadow); NaN: not measured
    float appearance = kNaN; // 0..1; a learned appearance model's score (the cascade's); NaN: the detector has none
    bool top_measured = true;  // false: the box's height is the verification's fixed-aspect guess (no top cue
                               // found); a tracker takes its bottom and sides, not its height
};

// A hypothesis measured at the bottom centre of its box.
inline Hypothesis hypothesis_of(const cv::Rect2f &box, float score, float strength, const char *source) {
    Hypothesis h;
    h.box = box;
    h.foot = {box.x + 0.5f * box.width, box.y + box.height};
    h.score = score;
    h.strength = strength;
    h.source = source;
    return h;
}

} // namespace hw
