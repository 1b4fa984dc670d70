#include "detect/shadow/part.hpp"

#include "base/part_registry.hpp"
#include "base/stopwatch.hpp"

namespace hw {

bool ShadowDetector::detect(const RoadContext &ctx, std::vector<Hypothesis> &out, StageTimes &times) {
    Stopwatch sh;
    const auto hyps = shadow_hypotheses(ctx.gray, ctx.lanes, ctx.camera, shadow_);
    const float hyp_ms = sh.ms();
    Stopwatch sv;
    const auto dets = verify_hypotheses(ctx.gray, hyps, ctx.lanes, ctx.camera, verify_);
    const float verify_ms = sv.ms();
    times.add("hypotheses", hyp_ms);
    times.add("verify", verify_ms);
    for (const Detection &d : dets) out.push_back(hypothesis_of(d, "shadow"));
    return true;
}

namespace {

// The part, its configuration section and its factory (base/part_registry.hpp).
const bool registered = register_part<Detector, ShadowParams>(
    "shadow", "shadow", [](const ShadowParams &p, const SectionLookup &c) {
        return std::make_unique<ShadowDetector>(p, c.get<VerifyParams>("verify"));
    });

} // namespace

} // namespace hw
