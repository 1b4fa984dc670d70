// detector.hpp - what every detector part offers a tracker part.
//
// A detector looks at one frame with the road's context (lane model and road area, the camera, and
// the road's motion when the composition runs the road-motion stage) and returns vehicle hypotheses.
// It does not decide when it runs: the tracker asks for a full detection when it needs one (the
// Kalman tracker every detect_every_n frames, the particle tracker every frame). To add a detector:
// write detect/detector_<name>.{hpp,cpp} with a class derived from Detector, and register it with its
// section at the end of its .cpp (base/part_registry.hpp; docs/ARCHITECTURE.md, "Adding a part").
#pragma once

#include "base/types.hpp"
#include "geometry/camera.hpp"

#include <memory>
#include <string>
#include <vector>

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

class Detector {
public:
    virtual ~Detector() = default;
    // Whether the part needs the road-motion stage (it then runs for the whole composition).
    virtual bool needs_road_motion() const { return false; }
    // A full detection over the road area. Appends to `out`, adds the wall time of its sub-stages to
    // `times`; returns false when it could not run this frame (e.g. no road motion yet).
    virtual bool detect(const RoadContext &ctx, std::vector<Hypothesis> &out, StageTimes &times) = 0;
    // Called once per frame after the tracker, whether or not detect() ran (parts with memory of past
    // frames keep it here).
    virtual void end_frame(const RoadContext &) {}
    virtual void reset() {}
};

} // namespace hw
