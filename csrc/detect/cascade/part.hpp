// cascade/part.hpp - detector part "cascade" (paper 004): the project's trained Haar cascade
// (cascade_scan.hpp, docs/detection.md) over the road area, each detection a hypothesis with the
// cascade's score (its confidence: the grouped windows' n / (n + neighbors_half), or the verifier's
// probability) as score and appearance, and the strongest window's last-stage sum as strength. Works on
// one image; needs no road motion. Loading the model happens when the part is built. Tracked with
// cascade.tracked_slices K > 1, each full detection scans one of K blocks of window sizes, in turn, so that no frame
// pays the whole scan (cascade_scan.hpp, tracked_slices: measured to lose far vehicles).
#pragma once

#include "detect/cascade/cascade_scan.hpp"
#include "detect/detector.hpp"

namespace hw {

class CascadeDetectorPart final : public Detector {
public:
    explicit CascadeDetectorPart(const CascadeParams &p) : cascade_(p), slices_(p.tracked_slices) {}
    // A single image: every window size. Tracked: the next block of window sizes (all of them with
    // tracked_slices 1), scanned and verified.
    bool detect(const RoadContext &ctx, std::vector<Hypothesis> &out, StageTimes &times) override;
    void reset() override { next_slice_ = 0; }

private:
    CascadeDetector cascade_;
    int slices_ = 1;
    int next_slice_ = 0;  // the block the next tracked detection scans
};

} // namespace hw
