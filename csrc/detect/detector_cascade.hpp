// detector_cascade.hpp - detector part "cascade" (paper 004): the project's trained Haar cascade
// (cascade_detector.hpp, docs/cascade.md) over the road area, each detection a hypothesis with the
// cascade's score (its confidence: the grouped windows' n / (n + neighbors_half), or the verifier's
// probability) as score and appearance, and the strongest window's last-stage sum as strength. Works on
// one image; needs no road motion. Loading the model happens when the part is built.
#pragma once

#include "detect/cascade_detector.hpp"
#include "detect/detector.hpp"

namespace hw {

class CascadeDetectorPart final : public Detector {
public:
    explicit CascadeDetectorPart(const CascadeParams &p) : cascade_(p) {}
    bool detect(const RoadContext &ctx, std::vector<Hypothesis> &out, StageTimes &times) override;

private:
    CascadeDetector cascade_;
};

} // namespace hw
