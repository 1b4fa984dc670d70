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
#include <map>
#include <memory>

namespace hw {

// The detection stage's vehicles on one image, in the order the stage gives them, and the horizon row they were
// found with (the configured camera's), and what it cost.
struct ImageDetections {
    std::vector<DetectedBox> boxes;
    float horizon_row = kNaN;
    StageTimes times;     // lanes and the detector parts' own stages
    float total_ms = 0.f;
};

class Pipeline {
public:
    explicit Pipeline(const Config &cfg);

    // One frame through every stage: lanes -> road motion (when a part needs it) -> vehicles (the
    // tracker part, asking the detector parts) -> geometry -> lead.
    // Throws std::invalid_argument for a frame of the wrong size or type, or a time going backwards.
    FrameOutput process(const Frame &frame);
    // The detection stage on one image alone, without touching tracking state (what `headway detect` writes):
    // the detector part `detector` of the registry built from this configuration, or, when it is empty, the
    // composition's own detector parts fused as in a tracked pipeline; the lanes of this image alone give the
    // road context. Throws std::invalid_argument for an unknown name or a part that needs the road's motion.
    ImageDetections detect_image(const std::string &detector, const cv::Mat &gray);
    void reset();
    // The car's own motion from the vehicle bus; any thread may set it (the loop reads it per frame).
    void set_ego_motion(const EgoMotion &ego) {
        ego_speed_mps_ = ego.speed_mps;
        ego_yaw_rate_rps_ = ego.yaw_rate_rps;
    }

    const Config &config() const { return cfg_; }

private:
    void check_frame(const cv::Mat &gray) const;
    // Where the lanes search the vanishing point: from scratch, self-calibration's search range while it searches,
    // its estimate +- lanes.horizon_tolerance_deg once converged; otherwise the configured camera's window.
    void set_lane_search();

    Config cfg_;
    LaneTracker lanes_;
    Parts parts_;                          // detectors, tracker (null: lanes only), road-motion stage
    std::vector<TrackState> last_tracks_;  // the tracker's output of the previous frame (road-motion stage; lanes: vehicles hide the road)
    ImageStatsMeter image_stats_;
    SelfCalibration calib_;
    HorizonTracker horizon_;
    TrackKinematics kinematics_;
    LeadSelector lead_;
    std::map<std::string, DetectorSet> single_parts_;  // detect_image()'s named parts, built on first use
    std::atomic<double> ego_speed_mps_{NAN}, ego_yaw_rate_rps_{NAN};
    double last_t_s_ = -1e300;
    double prev_t_s_ = NAN;  // the previous frame's time (yaw rate from the road motion)
};

} // namespace hw
