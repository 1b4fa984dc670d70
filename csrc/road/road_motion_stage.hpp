// road_motion_stage.hpp - the road plane's motion from the previous frame to this one (paper 000,
// section II-B), a stage of its own that runs when a part of the composition needs it (the parallax
// detector). Per frame:
//   features    markings, Harris corners, LK correspondences with the previous frame, started from
//               the predicted homography (ego speed from CAN informs it when known); corners inside
//               the boxes of the vehicles tracked in the previous frame are not used (not on the road);
//   homography  normalised DLT of the correspondences (road_model: the five-parameter road-motion fit
//               of road_motion_fit.hpp), constant-state Kalman filter with the 2-norm gate; the
//               prediction carries on when no measurement is accepted.
// Without any prediction (first frames with no CAN speed, after the filter was lost) the features
// would start from the identity, and near the camera a dash end then finds the next dash, 12 m on,
// as readily as its own (a consistent, wrong homography). So the travel is first found directly:
// the previous road band is warped with the flat-road homography of each travel in
// [0, search_max_speed_mps * dt] and the one leaving the smallest mean difference becomes the
// prediction (the dash period is far longer than a frame's travel, so this search cannot alias).
// The stage also keeps the road band (rows from band_above_horizon above the horizon to the bottom) at
// the parallax detector's pyramid level, this frame's and the previous one's, and hands both on.
#pragma once

#include "detect/parallax/part.hpp"
#include "road/lane_features.hpp"
#include "geometry/homography_dlt.hpp"
#include "geometry/homography_kalman.hpp"

#include <cmath>
#include <vector>

namespace hw {

// Section "homography": the DLT measurement and its Kalman filter.
struct HomographyParams {
    DltParams dlt;
    HomographyKalmanParams kalman;
    bool road_model = true;   // the measurement restricted to the road plane's motion (road_motion_fit.hpp)
    bool fit_tilt = true;     // also fit the plane's tilt (sixth parameter) for self-calibration's pitch and height
    bool measure_residual = false;  // report how well the estimate aligns the road (two full-frame warps a frame)
    void bind(ParamMap &m);
};

// What the homography stage did in the last frame (for tests and evaluation).
struct HomographyStep {
    HomographyKalman::Status status = HomographyKalman::Status::kNone;
    bool valid = false;          // an estimate exists after this frame
    int coast_frames = 0;
    int correspondences = 0;     // after the vehicle-box exclusion
    int used = 0;                // in the DLT fit
    double distance = NAN;       // ||H_meas - H_pred||_2 (road-band coordinates)
    cv::Matx33d H = cv::Matx33d::eye();  // estimate, previous -> current
};

class RoadMotionStage {
public:
    RoadMotionStage(const LaneFeatureParams &features, const HomographyParams &homography,
                    const ParallaxSection &parallax, const CameraParams &cam);
    // One frame. last_tracks: what the tracker reported for the previous frame (their confirmed boxes,
    // moved by their velocity, hold no road features). A gap longer than parallax.max_dt_s (or time
    // going back) starts the stage again.
    const RoadMotionFrame &update(const cv::Mat &gray, double t_s, const LaneModel &lanes, const EgoMotion &ego,
                                  const std::vector<TrackState> &last_tracks, StageTimes &times);
    void reset();
    // The mounting (pitch, yaw, height) the stage's road-motion model and feature search assume from now on:
    // self-calibration's estimate (the Kalman filter's normaliser keeps the camera the stage was built with).
    void set_camera(const CameraParams &cam) { cam_.pitch_deg = cam.pitch_deg; cam_.yaw_deg = cam.yaw_deg; cam_.height_m = cam.height_m; }

    const RoadMotionFrame &frame() const { return out_; }
    const HomographyStep &homography() const { return h_step_; }
    // The last frame's alignment residual over the road pixels (full resolution: the ego lane up to 40 m,
    // or the road area without a lane model, outside `detections` and the bonnet), gray levels; NaN
    // without an alignment.
    struct RoadResidual {
        float aligned = kNaN;      // mean |I_k - warp(I_{k-1}, H) - o|, o the fitted brightness change
        float unaligned = kNaN;    // mean |I_k - I_{k-1} - o'|, o' fitted alike
        float aligned_raw = kNaN;  // mean |I_k - warp(I_{k-1}, H)| (brightness change left in)
    };
    RoadResidual road_residual(const LaneModel &lanes, const std::vector<cv::Rect2f> &detections) const;

private:
    LaneFeatureParams fp_;
    HomographyParams hp_;
    ParallaxSection pp_;
    CameraParams cam_;
    HomographyKalman kf_;
    cv::Mat prev_, cur_;           // full frames (copies)
    cv::Mat prev_level_;           // previous road band at the detector's level
    double last_t_s_ = 0.0;
    bool started_ = false;
    int band_top_ = 0;
    HomographyStep h_step_;
    RoadMotionFrame out_;
};

} // namespace hw
