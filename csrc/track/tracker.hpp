// tracker.hpp - what every tracker part offers the pipeline.
//
// A tracker takes the frame and the hypotheses of the composition's detector parts, and reports
// tracks. It decides itself when a full detection runs and asks the detectors then (the Kalman tracker
// every detect_every_n frames, searching around its predictions between; the particle tracker every
// frame). To add a tracker: write track/tracker_<name>.{hpp,cpp} with a class derived from Tracker, and
// register it with its section at the end of its .cpp (base/part_registry.hpp; docs/ARCHITECTURE.md,
// "Adding a part").
#pragma once

#include "base/types.hpp"
#include "cues/detection_stage.hpp"
#include "geometry/camera.hpp"

#include <vector>

namespace hw {

struct FrameContext {
    const cv::Mat &gray;          // CV_8UC1 of the camera's configured size
    double t_s;                   // capture time, s
    int64_t number;               // frame number
    const LaneModel &lanes;       // this frame's lane model (may be invalid)
    const CameraParams &camera;
    EgoMotion ego;                // the car's own motion from CAN (NaN fields = unknown)
    const RoadMotionFrame *motion = nullptr;  // the road-motion stage's output; null when it does not run

    RoadContext road() const { return {gray, t_s, lanes, camera, motion}; }
};

class Tracker {
public:
    virtual ~Tracker() = default;
    // Advance one frame. Asks `detectors` for a full detection when it needs one, writes every live
    // track (confirmed or not) into `tracks`, adds the wall time of its sub-stages to `times`, and sets
    // `full_detection` if a full detection ran this frame.
    virtual void step(const FrameContext &ctx, DetectionStage &detectors, std::vector<TrackState> &tracks,
                      StageTimes &times, bool &full_detection) = 0;
    virtual void reset() = 0;
    // The camera as self-calibration has it (height, pitch, yaw), given after every frame while it runs. A
    // tracker that ranges its vehicles itself takes it; the detectors keep the configured camera.
    virtual void set_camera(const CameraParams &) {}
};

} // namespace hw
