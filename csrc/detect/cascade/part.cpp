#include "detect/cascade/part.hpp"

#include "base/part_registry.hpp"
namespace hw {

bool CascadeDetectorPart::detect(const RoadContext &ctx, std::vector<Hypothesis> &out, StageTimes &times) {
    const int slices = ctx.single_image ? 1 : slices_;
    const int slice = slices > 1 ? next_slice_ : 0;
    if (slices > 1) next_slice_ = (next_slice_ + 1) % slices;
    for (const CascadeDetection &d : cascade_.detect(ctx.gray, ctx.lanes, ctx.camera, slice, slices, &times)) {
        Hypothesis h = hypothesis_of(d.box, d.confidence, d.stage_sum, "cascade");
        h.appearance = d.confidence;
        out.push_back(h);
    }
    return true;
}

namespace {

// The part, its configuration section and its factory (base/part_registry.hpp).
const bool registered = register_part<Detector, CascadeParams>(
    "cascade", "cascade",
    [](const CascadeParams &p, const SectionLookup &) { return std::make_unique<CascadeDetectorPart>(p); });

} // namespace

} // namespace hw
