// self_calibration.hpp - the camera's pitch, yaw and height above the road, estimated while driving.
//
// The configured camera (camera: section) is the prior; every frame where both ego lane boundaries
// are measured and the car drives straight along its lane gives one measurement of each angle and
// of the height:
//   pitch  from the lanes' vanishing row v_h:    theta = atan((cy - v_h) / fy)
//   yaw    from the vanishing column u_vp:       psi   = atan((cx - u_vp) / fx)
//          (a camera turned right sees the road direction left of its axis; camera.hpp's convention)
//   height from the lane width: on a flat road the ego lane's image width grows linearly below the
//          horizon, w(v) = a (v - v_h) with a = fx W cos(theta) / (fy h) for a lane W metres wide, so
//          h = fx W cos(theta) / (fy a), a = (w(v1) - w(v2)) / (v1 - v2) from the two boundary lines.
// A second measurement of the yaw comes from the road plane's motion (parallax preset: the road-motion
// stage fits the road's homography between frames with the model of road_motion_fit.hpp around the camera
// it is given, which is this estimate): the car travels along the road, so a yaw error d puts a lateral
// part into the fitted translation, t_x = t_z tan(d) (level-camera axes of the assumed mounting):
//   yaw = assumed yaw - atan(t_x / t_z),  t from road_motion_translation().
// Used in the same frames as the lanes (same gates), when the stage accepted a measurement and the car
// moved (t_z > 0.2 m). Measured on calibration_drive with pitch and height right and the yaw 2 deg off:
// median error 0.02 deg, 0.12 deg per frame; with pitch and height also wrong the fit is biased (0.7 deg),
// so its weight is low until the lanes have fixed those (motion_yaw_noise_deg).
// Pitch and height from the road plane's motion: the stage also fits the road's motion with the plane's
// tilt e against the assumed mounting free (road_motion_fit.hpp, RoadMotion::tilt_*), so
//   pitch  = assumed pitch + e,
//   height = assumed height * (speed * dt) / fitted travel   (the fit's travel is scaled by the assumed height),
// the height needing no assumed lane width. Both are used once the estimate has converged (the fit is linearised
// around it and biased while it is off), in the lanes' frames (same gates). Measured per frame on calibration_drive
// with the camera exact: pitch 0.18 deg spread, height 1.4 % (the lanes': 0.5 deg, 6 %). The height is on by
// default; the pitch off: on the synthetic crest and sag it is as biased as the lanes' vanishing row (0.15-0.19
// deg) and pulled the estimate further (docs/RESULTS.md).
// The lane width is the height measurement in every preset (lanes need no vehicle bus and no road-motion fit);
// its price is the assumed lane width (road.lane_width_m: 3.6 m; real lanes are 3.25-3.75 m, so a few per cent
// of bias on a road with another standard), which the limits bound and the road's motion corrects where it runs.
//
// Each parameter is a scalar Kalman filter: random walk (process noise for slow load changes),
// initialised at the configured value with the prior's sigma; a measurement is used only when
//   - both ego boundaries were measured this frame (not carried over),
//   - the car is not changing lanes: the lateral offset in the lane moves slower than
//     max_lateral_rate_mps (a lane change crosses at ~1 m/s and turns the car against the lane,
//     which moves the vanishing column by fx * heading),
//   - the car is not on a curve: the path curvature |yaw rate| / speed (CAN or road motion, when known)
//     below max_curvature_1pm, and |yaw rate| below max_yaw_rate_rps (speed unknown), for curve_hold_s
//     since the last curved frame. On a curve of curvature k the lane stage's straight boundary fits
//     meet off the road's direction: a chord of x = k Z^2 / 2 through ranges Z1, Z2 meets the horizon
//     at fx k (Z1 + Z2) / 2 px, a yaw error of k Z_eff rad; measured on the synthetic curves, Z_eff =
//     11-15 m (a 2500 m radius: 0.3 deg, well over the 0.2 deg asked for, under a 0.02 rad/s yaw-rate gate),
//     hence the gate in curvature (1e-4 1/m: under 0.09 deg);
//   - the measurement is within gate_sigma of the estimate (innovation gate: a hill's crest or a
//     wrong marking is an outlier against a converged estimate); reacquire_after measurements gated
//     out in a row are no outliers but an estimate that went wrong (the lane tracker's first frames
//     from a wrong camera, an estimate stuck at a limit): its variance goes back to the prior's and
//     the next measurement is taken with the prior's gain,
// and the estimate is clamped to the configured value +- the limits. From scratch (from_scratch: true) the configured
// pitch and yaw are a starting value only: until pitch and yaw have converged (both 1-sigma within
// converged_sigma_deg) the estimate is searched over a wide range (pitch_min_deg .. pitch_max_deg, +-
// yaw_max_abs_deg), the first measurement from a believed lane model (paint along both ego lines) is the estimate,
// and the lane stage searches the vanishing point over that range too (LaneTracker::set_search_window,
// search_window()); so a camera given only its intrinsics and height converges. From then on the converged angles
// +- max_pitch_dev_deg / max_yaw_dev_deg guard the estimate (a wrong marking cannot drag it further). The height
// stays within the configured height +- max_height_dev. Off (enabled: false), the configured camera is used
// unchanged. The state (CalibrationState) says which of off, learning, converged (every 1-sigma within
// converged_sigma_*) or held at a limit the estimate is.
#pragma once

#include "base/params.hpp"
#include "base/types.hpp"
#include "geometry/camera.hpp"
#include "geometry/road_params.hpp"

#include <cmath>
#include <deque>
#include <utility>

namespace hw {

struct SelfCalibrationParams {
    bool enabled = true;               // estimate pitch, yaw and height while driving
    bool from_scratch = false;         // pitch and yaw unknown: searched over the ranges below, the lanes too
    double prior_sigma_deg = 2.0;      // 1-sigma trust in the configured pitch and yaw (from_scratch: none)
    double prior_sigma_height = 0.15;  // 1-sigma trust in the configured height, relative
    double angle_noise_deg = 0.5;      // 1-sigma of one frame's vanishing-point angle
    double height_noise = 0.06;        // 1-sigma of one frame's lane-width height, relative
    double angle_drift_deg_s = 0.01;   // random walk of the true angles (load, tyre pressure)
    double height_drift_s = 0.001;     // random walk of the true height, relative per sqrt(s)
    double pitch_min_deg = -5.0;       // from_scratch: the pitch is searched over [pitch_min_deg, pitch_max_deg]
    double pitch_max_deg = 20.0;
    double yaw_max_abs_deg = 10.0;     // from_scratch: the yaw likewise over +- this
    double max_pitch_dev_deg = 3.0;    // the pitch estimate stays within the configured pitch +- this (from_scratch:
                                       // within its converged value +- this, once converged)
    double max_yaw_dev_deg = 3.0;      // the yaw likewise
    double max_height_dev = 0.25;      // the estimate stays within the configured height * (1 +- this)
    RoadParams road;                   // section "road": lane_width_m, the ego-lane width assumed for the height
    double max_lateral_rate_mps = 0.3; // faster lateral motion in the lane is a lane change: no yaw update
    double lateral_rate_window_s = 0.5; // from_scratch: the lateral rate is the offset's slope over this long
    double search_sigmas = 3.0;        // until converged the lanes search the pitch estimate +- this many sigmas
    double max_yaw_rate_rps = 0.02;    // faster turning is a curve: no update (also without a known speed)
    double max_curvature_1pm = 1e-4;   // |yaw rate| / speed above this is a curve: no update (radius < 10 km)
    double curve_hold_s = 1.0;         // ... nor this long after it (the lane fits look ~15 m ahead)
    double yaw_rate_smoothing_s = 0.5; // time constant of the yaw rate the curve gate sees (camera shake averaged)
    double gate_sigma = 4.0;           // innovations beyond this many sigma are outliers
    int reacquire_after = 15;          // this many gated-out measurements in a row: the estimate is wrong, widen it
    bool road_motion = true;           // also measure the yaw from the road plane's motion (when it is fitted)
    double motion_yaw_noise_deg = 1.0; // 1-sigma of one frame's yaw from the road plane's motion
    bool motion_pitch = false;         // also measure the pitch from the road plane's tilt in its motion (fit_tilt);
                                       // off: on the synthetic hills it followed the hill more than the lanes do
    double motion_pitch_noise_deg = 0.2; // 1-sigma of one frame's pitch from the road plane's tilt (0.18 measured)
    bool motion_height = true;         // also measure the height: the CAN speed against the road's image motion
    double motion_height_noise = 0.015; // 1-sigma of one frame's height from the road's motion, relative (0.014 measured)
    double converged_sigma_deg = 0.1;  // pitch and yaw 1-sigma at or below this (and the height's below
                                       // converged_sigma_height): the state says converged (~25 lane frames)
    double converged_sigma_height = 0.01; // relative; the height's 1-sigma for "converged" (~40 lane frames)

    void bind(ParamMap &m);
};

// The car's yaw rate (rad/s, left positive) from the road plane's image motion H (pixels, previous ->
// current) over dt seconds, fitted by the road-motion stage around the mounting `cam`: the rotation R' of
// road_motion_rotation() about the level camera's vertical axis (y down; a turn d_psi to the left turns
// the scene right: R'(0,2) = sin d_psi). Separating the rotation from the travel matters: the former
// reading, the horizon row's points through H, took travel for rotation when the mounting was off (from
// 2 deg of pitch error it read a yaw rate that kept the curve gate shut: no calibration at all).
// NaN when dt is not positive.
double yaw_rate_of_road_motion(const cv::Matx33d &H, const CameraParams &cam, double dt_s);

// What the estimator is doing (the status, the tracks file and the CAN calibration frame report it).
enum class CalibrationState {
    kOff = 0,        // self_calibration.enabled is false: the configured camera is used as it is
    kLearning = 1,   // on, an uncertainty above the converged_sigma_* thresholds (at the start, or after a
                     // long time without lane measurements, or after a re-acquisition widened it)
    kConverged = 2,  // on, every uncertainty within the converged_sigma_* thresholds
    kAtLimit = 3     // on, an estimate held at a bound: the search range's end, the guard around the converged
                     // angles (max_*_dev_deg) or the height's (max_height_dev): the mounting moved or is outside
                     // the range, or the measurements are wrong; either way worth a look
};

// One frame's view of the calibration, with 1-sigma uncertainties.
struct CalibrationEstimate {
    double pitch_deg = NAN, yaw_deg = NAN, height_m = NAN;
    double pitch_sigma_deg = NAN, yaw_sigma_deg = NAN, height_sigma_m = NAN;
    int updates = 0;   // frames whose measurement was used
    bool active = false;  // self-calibration on
    CalibrationState state = CalibrationState::kOff;
};

class SelfCalibration {
public:
    SelfCalibration(const SelfCalibrationParams &p, const CameraParams &configured);
    // One frame: lanes as measured, ego speed (m/s) and yaw rate (rad/s, left positive; NaN unknown), frame time
    // (s), and the road plane's motion (state kNone: none) as fitted with camera() of the previous frame.
    void update(const LaneModel &lanes, double speed_mps, double yaw_rate_rps, double t_s,
                const RoadMotion &road = RoadMotion());
    // The configured camera with the estimated pitch, yaw and height.
    CameraParams camera() const;
    CalibrationEstimate estimate() const;
    // From scratch, until pitch and yaw have converged once: the whole range they may take (pitch_min_deg ..
    // pitch_max_deg, +- yaw_max_abs_deg); then their converged values +- max_*_dev_deg guard the estimate.
    bool searching() const { return p_.from_scratch && !anchored_; }
    // The pitches where the lanes' vanishing point may lie while searching: the estimate +- search_sigmas of its
    // sigma, within the search range, as (centre, half-width) in deg. At the start, the whole range whatever the
    // configured pitch: a pitch given or not, the lanes search the same window until the first measurement.
    std::pair<double, double> search_window() const;
    void reset();

private:
    struct Scalar {  // 1-D Kalman filter on a random walk
        double x = 0, var = 0;
        int rejected = 0;  // measurements gated out in a row
        bool diffuse = false;  // from scratch, no measurement yet: the first measurement is the estimate
        void predict(double q) { var += q; }
        // Kalman update with the innovation gate; after `reacquire` rejections in a row, var = max(var, prior_var)
        bool update(double z, double r, double gate_sigma, int reacquire, double prior_var);
    };
    SelfCalibrationParams p_;
    CameraParams cfg_;
    Scalar pitch_, yaw_, height_;  // deg, deg, relative to the configured height (1 = as configured)
    double last_t_ = NAN, last_offset_m_ = NAN;
    std::deque<std::pair<double, double>> offsets_;  // (t s, lateral offset m) over the last lateral_rate_window_s
    double last_curve_t_ = NAN;  // time of the last frame on a curve
    double yaw_rate_smooth_ = NAN;  // rad/s, the yaw rate low-passed over yaw_rate_smoothing_s
    int updates_ = 0;
    bool anchored_ = false;                   // pitch and yaw have converged once
    double anchor_pitch_ = NAN, anchor_yaw_ = NAN;  // deg, their values then: the centre of the guard
    void clamp_angles();
    bool yaw_update(double yaw, const CameraParams &assumed, const RoadMotion &road, bool settled,
                    double speed_mps, double dt);
};

} // namespace hw
