#include "detect/detector_cascade.hpp"

#include "base/stopwatch.hpp"

namespace hw {

bool CascadeDetectorPart::detect(const RoadContext &ctx, std::vector<Hypothesis> &out, StageTimes &times) {
    Stopwatch sw;
    for (const CascadeDetection &d : cascade_.detect(ctx.gray, ctx.lanes, ctx.camera)) {
        Hypothesis h;
        h.box = d.box;
        h.foot = {d.box.x + 0.5f * d.box.width, d.box.y + d.box.height};
        h.score = d.confidence;
        h.strength = d.stage_sum;
        h.source = "cascade";
        h.appearance = d.confidence;
        out.push_back(h);
    }
    times.add("cascade", sw.ms());
    return true;
}

} // namespace hw
