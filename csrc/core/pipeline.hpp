// pipeline.hpp - the per-frame code path, shared by the real-time loop and offline process().
#pragma once

#include "base/types.hpp"
#include "capture/image_stats.hpp"
#include "core/config.hpp"
#include "core/parts.hpp"
#include "fcw/lead_selection.hpp"
#include "geometry/horizon.hpp"
#include "geometry/self_calibration.hpp"
#include "geometry/track_kinematics.hpp"
#include "lanes/lane_tracker.hpp"

#include <atomic>
#include <memory>

namespace hw {

class Pipeline {
public:
    explicit Pipeline(const Config &cfg);

    // One frame through every stage: lanes -> road motion (when a part needs it) -> vehicles (the
    // tracker part, asking the detector parts) -> geometry -> lead.
    // Throws std::invalid_argument for a frame of the wrong size or type, or a time going backwards.
    FrameOutput process(const Frame &frame);
    // Single-image units without touching tracking state: "lanes", "hypotheses" (the shadow detector's
    // hypotheses before verification), "detect" (the composition's detector parts that need no road
    // motion); the two-frame units "homography" and "parallax" take frames stacked vertically
    // (core/parallax_stage.hpp).
    FrameOutput run_stage(const std::string &stage, const cv::Mat &gray);
    void reset();
    // The car's own motion from the vehicle bus; any thread may set it (the loop reads it per frame).
    void set_ego_motion(const EgoMotion &ego) {
        ego_speed_mps_ = ego.speed_mps;
        ego_yaw_rate_rps_ = ego.yaw_rate_rps;
    }

    const Config &config() const { return cfg_; }

private:
    void check_frame(const cv::Mat &gray) const;

    Config cfg_;
    LaneTracker lanes_;
    Parts parts_;                          // detectors, tracker (null: lanes only), road-motion stage
    std::vector<TrackState> last_tracks_;  // the tracker's output of the previous frame (road-motion stage; lanes: vehicles hide the road)
    ImageStatsMeter image_stats_;
    SelfCalibration calib_;
    HorizonTracker horizon_;
    TrackKinematics kinematics_;
    LeadSelector lead_;
    std::atomic<double> ego_speed_mps_{NAN}, ego_yaw_rate_rps_{NAN};
    double last_t_s_ = -1e300;
    double prev_t_s_ = NAN;  // the previous frame's time (yaw rate from the road motion)
};

} // namespace hw
