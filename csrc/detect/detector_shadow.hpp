// detector_shadow.hpp - detector part "shadow" (the thesis): shadow hypotheses under vehicles
// (shadow.hpp), each verified by the vertical edges of its sides (verify.hpp). Works on one image;
// needs no road motion. In a composition of several detectors it gives its shadow hypotheses unverified,
// and the merge verifies them with the others' (merge_hypotheses.hpp).
#pragma once

#include "detect/detector.hpp"
#include "detect/verify.hpp"

namespace hw {

class ShadowDetector final : public Detector {
public:
    ShadowDetector(const ShadowParams &shadow, const VerifyParams &verify) : shadow_(shadow), verify_(verify) {}
    bool detect(const RoadContext &ctx, std::vector<Hypothesis> &out, StageTimes &times) override;
    // The shadow hypotheses themselves (bottom edge, its road gray level and depth), for the merge's one
    // verification (merge_hypotheses.hpp), which is this part's own.
    bool unverified(const RoadContext &ctx, std::vector<Hypothesis> &out, StageTimes &times) override;

private:
    ShadowParams shadow_;
    VerifyParams verify_;
};

} // namespace hw
