// detector.hpp - what every detector part offers a tracker part.
//
// A detector looks at one frame with the road's context (lane model and road area, the camera, and
// the road's motion when the composition runs the road-motion stage) and returns vehicle hypotheses.
// It does not decide when it runs: the tracker asks for a full detection when it needs one (the
// Kalman tracker every detect_every_n frames, the particle tracker every frame). To add a detector:
// write detect/<name>/part.{hpp,cpp} with a class derived from Detector, and register it with its
// section at the end of its .cpp (base/part_registry.hpp; docs/ARCHITECTURE.md, "Adding a part").
#pragma once

#include "base/types.hpp"
#include "cues/hypothesis.hpp"

#include <memory>
#include <string>
#include <vector>

namespace hw {

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
