// parallax_tracker.hpp - the paper-000 pipeline as a VehicleTracker: lane-marking features ->
// filtered road homography -> aligned-difference detector -> joint particle filter.
//
// Per frame:
//   features    markings, Harris corners, LK correspondences with the previous frame, started from
//               the predicted homography (ego speed from CAN informs it when known); corners inside
//               the boxes of tracked vehicles are not used (they are not on the road);
//   homography  normalised DLT of the correspondences, constant-state Kalman filter with the 2-norm
//               gate; the prediction carries on when no measurement is accepted;
//   parallax    while the filter holds an estimate, the previous frame's road band is warped onto the
//               current one and its differences become measurements;
//   particles   the joint SIR filter takes the measurements, confirms entries, removes exits.
// Without any prediction (first frames with no CAN speed, after the filter was lost) the features
// would start from the identity, and near the camera a dash end then finds the next dash, 12 m on,
// as readily as its own (a consistent, wrong homography). So the travel is first found directly:
// the previous road band is warped with the flat-road homography of each travel in
// [0, search_max_speed_mps * dt] and the one leaving the smallest mean difference becomes the
// prediction (the dash period is far longer than a frame's travel, so this search cannot alias).
// A second difference is taken against the frame long_gap frames back, warped with the product of the
// filtered homographies since: long_gap times the parallax of a vehicle keeping its distance (far
// vehicles at 30 fps move a fraction of a pixel per frame; the paper ran at 5-10 fps); its regions
// count where the one-frame difference found none (fast vehicles smear over long gaps).
// Every frame with an alignment is a full detection: the detector always scans the whole road area.
// The vehicle boxes come from the measurement regions (bottom edge and width), so the range, TTC and
// lead stages treat them like any other track.
#pragma once

#include "detect/lane_features.hpp"
#include "detect/parallax_detector.hpp"
#include "geometry/homography_dlt.hpp"
#include "geometry/homography_kalman.hpp"
#include "track/particle_filter.hpp"
#include "track/tracker.hpp"

#include <deque>
#include <vector>

namespace hw {

// Section "homography": the DLT measurement and its Kalman filter.
struct HomographyParams {
    DltParams dlt;
    HomographyKalmanParams kalman;
    bool road_model = true;   // the measurement restricted to the road plane's motion (road_motion_fit.hpp)
    void bind(ParamMap &m);
};

// Section "parallax": the detector and how the tracker feeds it.
struct ParallaxTrackerParams {
    ParallaxParams detect;
    double band_above_horizon = 0.08;  // share of the image height above the horizon kept in the road band
    double road_range_m = 120.0;       // m; the road area is continued toward the vanishing point up to here
    double road_lanes_each_side = 2.0; // lane widths; the road area covers at least the ego lane +- this
    double hood_frac = 0.0;            // share of the image height at the bottom that is the car's bonnet
    bool exclude_vehicle_corners = true;  // road features inside confirmed vehicles' boxes are not used
    double max_dt_s = 1.0;             // s; a longer gap between frames starts everything again
    int long_gap = 3;                  // frames back of the second, long-gap difference (0, 1: none)
    double long_gap_min_range_m = 0.0;   // m; the long-gap difference covers the road beyond this range only (0: all)
    double search_max_speed_mps = 45.0;  // m/s; travel searched when there is no prediction
    int search_steps = 24;             // travels tried between 0 and that

    void bind(ParamMap &m);
};
// What the homography stage did in the last frame (for tests, run_stage and evaluation).
struct HomographyStep {
    HomographyKalman::Status status = HomographyKalman::Status::kNone;
    bool valid = false;          // an estimate exists after this frame
    int coast_frames = 0;
    int correspondences = 0;     // after the vehicle-box exclusion
    int used = 0;                // in the DLT fit
    double distance = NAN;       // ||H_meas - H_pred||_2 (road-band coordinates)
    cv::Matx33d H = cv::Matx33d::eye();  // estimate, previous -> current
};

class ParallaxTracker final : public VehicleTracker {
public:
    ParallaxTracker(const LaneFeatureParams &features, const HomographyParams &homography,
                    const ParallaxTrackerParams &parallax, const ParticleParams &particles, const CameraParams &cam);
    void step(const FrameContext &ctx, std::vector<TrackState> &tracks, StageTimes &times,
              bool &full_detection) override;
    void reset() override;

    const HomographyStep &homography() const { return h_step_; }
    RoadMotion road_motion() const override;
    const ParallaxFrame &detection() const { return detection_; }
    // The last frame's alignment residual over the road pixels (full resolution: the ego lane up to 40 m,
    // or the road area without a lane model, outside the detections and the bonnet), gray levels; NaN
    // without an alignment.
    struct RoadResidual {
        float aligned = kNaN;      // mean |I_k - warp(I_{k-1}, H) - o|, o the fitted brightness change
        float unaligned = kNaN;    // mean |I_k - I_{k-1} - o'|, o' fitted alike
        float aligned_raw = kNaN;  // mean |I_k - warp(I_{k-1}, H)| (brightness change left in)
    };
    RoadResidual road_residual(const LaneModel &lanes) const;

private:
    LaneFeatureParams fp_;
    HomographyParams hp_;
    ParallaxTrackerParams pp_;
    CameraParams cam_;
    HomographyKalman kf_;
    JointParticleFilter pf_;
    cv::Mat prev_, cur_;           // full frames (copies)
    cv::Mat prev_level_;           // previous road band at the detector's level
    std::deque<std::pair<cv::Mat, cv::Matx33d>> history_;  // older bands at the level, each with H to the next
    double last_t_s_ = 0.0;
    bool started_ = false;
    HomographyStep h_step_;
    ParallaxFrame detection_;
    int band_top_ = 0;
    int hood_row() const { return cam_.height - int(std::lround(pp_.hood_frac * cam_.height)); }
    std::vector<TrackState> last_tracks_;
};

} // namespace hw
