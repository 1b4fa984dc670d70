// track_kinematics.hpp - range, lateral offset, range rate and both TTCs for every track.
//
// Range and lateral come from the bottom-centre of the box on the flat road (flat_road.hpp). A
// constant-acceleration Kalman filter per track on [Z, dZ/dt, d2Z/dt2] gives the range rate and the
// relative acceleration (a braking lead shows in it before the range rate has grown: the FCW uses it
// for its required deceleration); its measurement noise follows the row uncertainty through
// dZ/dv = -Z^2/(fy h), so far vehicles are trusted less.
// The scale-based TTC needs no calibration: for a rear face of fixed width, w ~ 1/Z, so
// d(ln w)/dt = -(dZ/dt)/Z = 1/TTC; we fit the slope of ln w over a short window. While the range
// filter does not trust its rate yet, the closing speed the scale implies (Z d(ln w)/dt) must agree
// with the filter's within 3 sigma of both, or no scale TTC is given (a far box's pixel of jitter).
// Optionally (scale_rate_fusion) the fit also updates the filter's rate.
// A tracker that estimates range and range rate itself (the phd preset's UKF) reports range_m already
// set: its range and lateral are kept, its rate once its sigma is below kRateKnownSigma, and the two TTCs
// are added here; its unsettled rate still judges the scale TTC, within 4 sigma of both (kUnsettledRateSigmas).
#pragma once

#include "base/params.hpp"
#include "base/types.hpp"
#include "geometry/camera.hpp"

#include <Eigen/Dense>

#include <deque>
#include <unordered_map>
#include <vector>

namespace hw {

// A range rate is reported (and the range TTC given) once its 1-sigma is below this, m/s.
constexpr double kRateKnownSigma = 2.0;

struct KinematicsParams {
    double jerk_sigma_mps3 = 2.0;    // white-jerk process noise of the range filter
    double min_row_sigma_px = 0.7;   // floor of the contact-row uncertainty
    double ego_front_m = 2.0;        // camera to the front bumper: TTC is to the bumper
    double min_closing_mps = 0.3;    // slower closing is "not closing": TTC not available
    int scale_window = 12;           // frames in the ln(w) slope fit
    double scale_min_span_s = 0.3;   // the fit needs at least this much time
    bool scale_rate_fusion = false;  // the scale change also updates the range filter's rate
    double scale_jump_closing_mps = 40.0;  // a faster width change between frames restarts the scale fit
    double scale_jump_px = 4.0;            // edge noise allowed on top of it
    double scale_margin_px = 3.0;          // the box's width beyond the vehicle's, taken off before the fit
    double box_margin_px = 0.0;            // a tracked box's reported sides: its width less this
    double box_margin_frac = 0.0;          // and this share of its height (the detector's margin), half each side

    void bind(ParamMap &m) {
        m.add("jerk_sigma_mps3", jerk_sigma_mps3, 0.01, 100.0,
              "m/s^3; process noise of the range filter (white jerk); 2 lets the relative acceleration follow "
              "a lead that starts braking at 0.3 g within about a second while keeping it quiet when nobody brakes");
        m.add("min_row_sigma_px", min_row_sigma_px, 0.05, 20.0,
              "px; floor of the contact-row uncertainty used for range sigma and filter noise");
        m.add("ego_front_m", ego_front_m, 0.0, 10.0,
              "m; camera to the front bumper; TTC is measured to the bumper, not the windscreen");
        m.add("min_closing_mps", min_closing_mps, 0.0, 10.0,
              "m/s; below this closing speed TTC is not available (it would be huge and meaningless)");
        m.add("scale_window", scale_window, 3, 100,
              "frames; window of the scale-change fit, and the track age before a scale TTC is given; 12 frames = 0.4 s at 30 fps smooths 1 px width noise");
        m.add("scale_min_span_s", scale_min_span_s, 0.0, 10.0,
              "s; the scale fit needs at least this time span before it reports a TTC");
        m.add("scale_jump_closing_mps", scale_jump_closing_mps, 1.0, 1000.0,
              "m/s; a box width changing between two frames faster than a vehicle closing at this speed would (plus "
              "scale_jump_px) restarts the scale-change fit (docs/tracking.md)");
        m.add("scale_jump_px", scale_jump_px, 0.0, 100.0,
              "px; edge noise of the box width allowed on top of scale_jump_closing_mps before the scale fit restarts");
        m.add("scale_margin_px", scale_margin_px, 0.0, 50.0,
              "px; how much wider than the vehicle's rear the detector's box is (the margin its training boxes "
              "were drawn with), taken off the width before the scale fit: a constant margin makes the scale TTC "
              "too long by margin / width (docs/tracking.md)");
        m.add("box_margin_px", box_margin_px, 0.0, 50.0,
              "px; a tracked vehicle's box is reported box_margin_px + box_margin_frac x its height narrower, half "
              "off each side: the margin a learned detector's boxes carry beyond the vehicle's sides (docs/tracking.md)");
        m.add("box_margin_frac", box_margin_frac, 0.0, 0.5,
              "share of a tracked box's height added to box_margin_px in its reported width (docs/tracking.md)");
        m.add("scale_rate_fusion", scale_rate_fusion,
              "the box's scale change also measures the range rate (dZ/dt = -Z d(ln w)/dt) in the range filter "
              "(docs/tracking.md)");
    }
};

class TrackKinematics {
public:
    TrackKinematics(const KinematicsParams &p, const CameraParams &cam) : p_(p), cam_(cam) {}
    // Fills range_m, range_sigma_m, lateral_m, range_rate_mps, ttc_s, ttc_scale_s of every track.
    void update(std::vector<TrackState> &tracks, double horizon_row, double t_s);
    void reset() { state_.clear(); }
    void set_camera(const CameraParams &cam) { cam_ = cam; }  // self-calibration's estimate

private:
    struct State {
        Eigen::Vector3d x;                  // range, range rate, relative acceleration
        Eigen::Matrix3d P;                  // covariance
        double t = 0;
        std::deque<std::pair<double, double>> log_w;  // (t, ln width)
    };
    // ln w slope over the window (NaN until the window is full), adding this frame's width; a width step
    // impossible at range_m restarts the window.
    double scale_fit(const TrackState &tr, State &s, double t_s, double range_m, double &scale_se) const;
    // For a track whose tracker gave range and range rate: the range TTC from them and the scale TTC.
    void given_range_ttcs(TrackState &tr, State &s, double t_s) const;

    KinematicsParams p_;
    CameraParams cam_;
    std::unordered_map<int, State> state_;
};

} // namespace hw
