#include "track/particles/part.hpp"

#include "base/part_registry.hpp"
#include "base/stopwatch.hpp"

namespace hw {

void ParticleTracker::reset() {
    pf_.reset();
    clock_.reset();
}

void ParticleTracker::step(const FrameContext &ctx, DetectionStage &detectors, std::vector<TrackState> &tracks,
                           StageTimes &times, bool &full_detection) {
    bool gap = false;
    const double dt = clock_.step(ctx.t_s, gap);
    if (gap) pf_.reset();

    std::vector<Hypothesis> hyps;
    full_detection = detectors.detect(ctx.road(), hyps, times);
    Stopwatch sw;
    std::vector<PointMeasurement> z;
    z.reserve(hyps.size());
    for (const Hypothesis &h : hyps) z.push_back({h.foot, h.box, h.strength});
    const cv::Point2f vp = ctx.motion ? ctx.motion->vp : road_vanishing_point(ctx.lanes, cam_);
    pf_.step(dt, z, ctx.gray.size(), vp);
    pf_.report(tracks);
    times.add("particles", sw.ms());
}

namespace {

// The part, its configuration section and its factory (base/part_registry.hpp).
const bool registered = register_part<Tracker, ParticleParams>(
    "particles", "particles", [](const ParticleParams &p, const SectionLookup &c) {
        return std::make_unique<ParticleTracker>(p, c.get<CameraParams>("camera"));
    });

} // namespace

} // namespace hw
