// shadow/part.hpp - detector part "shadow" (the thesis): shadow hypotheses under vehicles
// (shadow.hpp), each verified by the vertical edges of its sides (verify.hpp). Works on one image;
// needs no road motion. Beside a learned detector its detections are cues (detect/fuse_hypotheses.hpp).
#pragma once

#include "detect/detector.hpp"
#include "cues/verify.hpp"

namespace hw {

class ShadowDetector final : public Detector {
public:
    ShadowDetector(const ShadowParams &shadow, const VerifyParams &verify) : shadow_(shadow), verify_(verify) {}
    bool detect(const RoadContext &ctx, std::vector<Hypothesis> &out, StageTimes &times) override;

private:
    ShadowParams shadow_;
    VerifyParams verify_;
};

} // namespace hw
