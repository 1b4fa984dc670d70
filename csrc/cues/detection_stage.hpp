// detection_stage.hpp - what a tracker part asks of the composition's detectors: a full detection, now or begun
// on a worker thread and taken some frames later. The detector parts' DetectorSet (detect/fuse_hypotheses.hpp)
// is the one implementation; a tracker sees only this, so track/ never includes detect/.
#pragma once

#include "base/types.hpp"
#include "cues/hypothesis.hpp"

#include <cstdint>
#include <vector>

namespace hw {

class DetectionStage {
public:
    virtual ~DetectionStage() = default;
    // The vehicles of this frame (several parts' fused); false if no part could run.
    virtual bool detect(const RoadContext &ctx, std::vector<Hypothesis> &out, StageTimes &times) = 0;
    // Whether start() can run this composition (no part needs the road's motion).
    virtual bool can_start() const = 0;
    // detect() on a worker thread, on copies of what it reads.
    virtual void start(const RoadContext &ctx, int64_t frame_number) = 0;
    // Waits for the detection start() began and gives its vehicles as detect() does.
    virtual bool finish(std::vector<Hypothesis> &out, StageTimes &times) = 0;
};

} // namespace hw
