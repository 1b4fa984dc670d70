// particles/part.hpp - tracker part "particles" (paper 000, section III): the joint SIR particle
// filter of particle_filter.hpp, with entries confirmed through its transitory period and exits
// managed by the filter. It asks the detector parts every frame; each hypothesis is a measurement at
// its foot point (the mid-lower point of a parallax region, the bottom centre of a shadow box).
#pragma once

#include "track/frame_clock.hpp"
#include "track/particles/particle_filter.hpp"
#include "track/tracker.hpp"

namespace hw {

class ParticleTracker final : public Tracker {
public:
    ParticleTracker(const ParticleParams &p, const CameraParams &cam) : pf_(p, cam), cam_(cam), clock_(p.max_dt_s) {}
    void step(const FrameContext &ctx, DetectionStage &detectors, std::vector<TrackState> &tracks, StageTimes &times,
              bool &full_detection) override;
    void reset() override;

private:
    JointParticleFilter pf_;
    CameraParams cam_;
    FrameClock clock_;
};

} // namespace hw
