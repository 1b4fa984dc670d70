// tracker.hpp - what every vehicle tracker offers the pipeline.
//
// A tracker owns its detector(s): the thesis tracker decides itself when a full detection runs and
// when it only searches around its predictions; the particle and PHD trackers will do likewise.
#pragma once

#include "core/types.hpp"
#include "fcw/lead_selection.hpp"
#include "geometry/camera.hpp"

#include <memory>
#include <vector>

namespace hw {

struct FrameContext {
    const cv::Mat &gray;          // CV_8UC1 of the camera's configured size
    double t_s;                   // capture time, s
    int64_t number;               // frame number
    const LaneModel &lanes;       // this frame's lane model (may be invalid)
    const CameraParams &camera;
    EgoMotion ego;                // the car's own motion from CAN (NaN fields = unknown)
};

class VehicleTracker {
public:
    virtual ~VehicleTracker() = default;
    // Advance one frame. Writes every live track (confirmed or not) into `tracks`, adds the wall time
    // of its sub-stages to `times`, and sets `full_detection` if a full detection ran this frame.
    virtual void step(const FrameContext &ctx, std::vector<TrackState> &tracks, StageTimes &times,
                      bool &full_detection) = 0;
    virtual void reset() = 0;
    // The road plane's motion of the last step, for trackers that estimate it (none by default).
    virtual RoadMotion road_motion() const { return {}; }
};

} // namespace hw
