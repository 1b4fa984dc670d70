#include "geometry/self_calibration.hpp"

#include "geometry/road_motion_fit.hpp"

#include <algorithm>
#include <deque>

namespace hw {

namespace {
constexpr double kDeg = M_PI / 180.0;
bool at_bound(double x, double lo, double hi) { return x <= lo + 1e-9 || x >= hi - 1e-9; }
// least-squares slope of (t, y) samples (at least two distinct times)
double slope(const std::deque<std::pair<double, double>> &s) {
    double mt = 0, my = 0;
    for (const auto &p : s) { mt += p.first; my += p.second; }
    mt /= double(s.size());
    my /= double(s.size());
    double stt = 0, sty = 0;
    for (const auto &p : s) { stt += (p.first - mt) * (p.first - mt); sty += (p.first - mt) * (p.second - my); }
    return stt > 0 ? sty / stt : 0.0;
}
}

void SelfCalibrationParams::bind(ParamMap &m) {
    m.add("enabled", enabled, "estimate the camera's pitch, yaw and height from the lanes while driving; "
                              "false = the camera section is used as configured");
    m.add("from_scratch", from_scratch,
          "pitch and yaw not known: searched from the lanes, the limits then around the converged estimate; "
          "true by default when a configuration file's camera section has no pitch_deg");
    m.add("prior_sigma_deg", prior_sigma_deg, 0.01, 30.0,
          "deg; 1-sigma trust in the configured pitch and yaw (the prior); a surveyed mounting can say 0.2");
    m.add("prior_sigma_height", prior_sigma_height, 0.001, 1.0,
          "relative; 1-sigma trust in the configured camera height");
    m.add("angle_noise_deg", angle_noise_deg, 0.01, 10.0,
          "deg; 1-sigma of one frame's vanishing-point angle (marking edges, camera shake ~0.15 deg)");
    m.add("height_noise", height_noise, 0.001, 1.0,
          "relative; 1-sigma of one frame's height from the lane width (dashes, line-fit noise)");
    m.add("angle_drift_deg_s", angle_drift_deg_s, 0.0, 10.0,
          "deg/sqrt(s); random walk of the true angles (load, tyre pressure); bounds how long the estimate remembers");
    m.add("height_drift_s", height_drift_s, 0.0, 1.0, "relative/sqrt(s); random walk of the true height");
    m.add("pitch_min_deg", pitch_min_deg, -30.0, 30.0,
          "deg; from_scratch: lowest pitch searched (the lanes' vanishing point too) until pitch and yaw converge");
    m.add("pitch_max_deg", pitch_max_deg, -30.0, 30.0,
          "deg; from_scratch: highest pitch searched (looking down) until pitch and yaw converge");
    m.add("yaw_max_abs_deg", yaw_max_abs_deg, 0.0, 30.0, "deg; from_scratch: the yaw is searched within +- this");
    m.add("max_pitch_dev_deg", max_pitch_dev_deg, 0.0, 20.0,
          "deg; the pitch estimate stays within the configured pitch +- this (from_scratch: within its converged "
          "value +- this, once converged); a wrong marking cannot drag it further");
    m.add("max_yaw_dev_deg", max_yaw_dev_deg, 0.0, 20.0,
          "deg; the yaw estimate stays within the configured yaw +- this (from_scratch: its converged value's)");
    m.add("max_height_dev", max_height_dev, 0.0, 0.9,
          "relative; the height estimate stays within the configured height * (1 +- this)");
    m.add("lateral_rate_window_s", lateral_rate_window_s, 0.05, 10.0,
          "s; from_scratch: the lateral rate is the offset's least-squares slope over this long (measured from half of "
          "it on); otherwise frame to frame");
    m.add("search_sigmas", search_sigmas, 1.0, 20.0,
          "sigma; from_scratch, until converged the lanes search the vanishing point within the pitch estimate +- this many of "
          "its sigmas (within the search range; at least lanes.horizon_tolerance_deg)");
    m.add("max_lateral_rate_mps", max_lateral_rate_mps, 0.0, 5.0,
          "m/s; faster lateral motion within the lane is a lane change (~1 m/s), when the car is turned against "
          "the lane: no measurement");
    m.add("max_yaw_rate_rps", max_yaw_rate_rps, 0.0, 1.0,
          "rad/s; turning faster (CAN or road motion) is a curve, where the boundaries' tangents miss the road "
          "direction: no measurement");
    m.add("reacquire_after", reacquire_after, 1, 10000,
          "measurements; this many gated out in a row mean the estimate went wrong (a wrong start, stuck at a "
          "limit): its uncertainty goes back to the prior's so that the measurements are taken again");
    m.add("max_curvature_1pm", max_curvature_1pm, 0.0, 1.0,
          "1/m; a path curvature |yaw rate| / speed above this is a curve (1e-4: radius under 10 km), where the "
          "lanes' straight fits meet k * ~13 m off the road direction (0.07 deg at 1e-4): no measurement");
    m.add("curve_hold_s", curve_hold_s, 0.0, 30.0,
          "s; no measurement for this long after the last frame on a curve (the lane fits look ~15 m ahead)");
    m.add("road_motion", road_motion, "also measure the yaw from the road plane's motion where it is fitted (parallax "
                                      "preset): the lateral part of the car's travel against the assumed mounting");
    m.add("motion_yaw_noise_deg", motion_yaw_noise_deg, 0.01, 30.0,
          "deg; 1-sigma of one frame's yaw from the road plane's motion (0.12 deg measured with the rest of the "
          "mounting right, biased by ~0.7 deg while pitch and height are 2 deg / 15 % off)");
    m.add("yaw_rate_smoothing_s", yaw_rate_smoothing_s, 0.0, 10.0,
          "s; time constant of the low-pass on the yaw rate the curve gate tests (the road's motion carries the "
          "camera's shake; a bus yaw rate is smooth already)");
    m.add("motion_pitch", motion_pitch,
          "also measure the pitch from the road plane's motion (homography.fit_tilt) once converged; off: on "
          "crests and sags it is as biased as the lanes (docs/calibration.md)");
    m.add("motion_pitch_noise_deg", motion_pitch_noise_deg, 0.01, 30.0,
          "deg; 1-sigma of one frame's pitch from the road plane's tilt (0.18 deg measured, calibration_drive)");
    m.add("motion_height", motion_height,
          "also measure the height from the road plane's motion once converged (parallax preset, needs the CAN "
          "speed); needs no assumed lane width (docs/calibration.md)");
    m.add("motion_height_noise", motion_height_noise, 0.001, 1.0,
          "relative; 1-sigma of one frame's height from the road's motion (1.4 % measured on calibration_drive, "
          "0.2 % bias; the lanes' is 6 %)");
    m.add("converged_sigma_deg", converged_sigma_deg, 0.001, 30.0,
          "deg; the state says converged when the pitch's and the yaw's 1-sigma are at or below this (and the "
          "height's below converged_sigma_height)");
    m.add("converged_sigma_height", converged_sigma_height, 0.0001, 1.0,
          "relative; the height's 1-sigma for the converged state; 1 %, a third of the 3 % asked, after ~40 "
          "frames of lanes (one frame: 6 %)");
    m.add("gate_sigma", gate_sigma, 1.0, 100.0,
          "sigma; a measurement farther from the estimate than this (estimate and measurement sigma together) is "
          "an outlier (a crest, a wrong marking)");
}

double yaw_rate_of_road_motion(const cv::Matx33d &H, const CameraParams &cam, double dt_s) {
    if (!(dt_s > 0)) return NAN;
    const cv::Matx33d R = road_motion_rotation(H, cam);
    return std::atan2(R(0, 2), R(2, 2)) / dt_s;
}

bool SelfCalibration::Scalar::update(double z, double r, double gate_sigma, int reacquire, double prior_var) {
    if (diffuse) {  // the estimate starts at the first measurement, whatever the configured value
        x = z;
        var = r;
        diffuse = false;
        return true;
    }
    const double s = var + r;  // innovation variance
    const double innov = z - x;
    if (innov * innov > gate_sigma * gate_sigma * s) {
        if (++rejected >= reacquire) {  // persistently off: the estimate, not the measurements, is wrong
            var = std::max(var, prior_var);
            rejected = 0;
        }
        return false;
    }
    rejected = 0;
    const double k = var / s;  // x += K (z - x), P = (1 - K) P
    x += k * innov;
    var *= 1.0 - k;
    return true;
}

SelfCalibration::SelfCalibration(const SelfCalibrationParams &p, const CameraParams &configured)
    : p_(p), cfg_(configured) {
    reset();
}

void SelfCalibration::reset() {
    anchored_ = false;
    anchor_pitch_ = anchor_yaw_ = NAN;
    pitch_ = {cfg_.pitch_deg, p_.prior_sigma_deg * p_.prior_sigma_deg};
    yaw_ = {cfg_.yaw_deg, p_.prior_sigma_deg * p_.prior_sigma_deg};
    // From scratch the configured pitch and yaw say nothing: their uncertainty is the search range's (the lanes search
    // all of it) and the first measurement is the estimate, so a pitch given or not gives the same estimate from then
    // on.
    pitch_.diffuse = yaw_.diffuse = p_.from_scratch;
    if (p_.from_scratch) {
        pitch_.var = std::pow(p_.pitch_max_deg - p_.pitch_min_deg, 2);
        yaw_.var = std::pow(2.0 * p_.yaw_max_abs_deg, 2);
    }
    clamp_angles();  // a configured value outside the search range starts at its end
    height_ = {1.0, p_.prior_sigma_height * p_.prior_sigma_height};
    last_t_ = last_offset_m_ = last_curve_t_ = yaw_rate_smooth_ = NAN;
    offsets_.clear();
    updates_ = 0;
}

void SelfCalibration::update(const LaneModel &lanes, double speed_mps, double yaw_rate_rps, double t_s,
                             const RoadMotion &road) {
    // the road plane's motion was fitted around this estimate (before this frame's update)
    const CameraParams assumed = camera();
    if (!p_.enabled) return;
    const bool settled = estimate().state == CalibrationState::kConverged;
    const double dt = std::isfinite(last_t_) ? std::max(0.0, t_s - last_t_) : 0.0;
    last_t_ = t_s;
    pitch_.predict(p_.angle_drift_deg_s * p_.angle_drift_deg_s * dt);
    yaw_.predict(p_.angle_drift_deg_s * p_.angle_drift_deg_s * dt);
    height_.predict(p_.height_drift_s * p_.height_drift_s * dt);

    // on a curve (path curvature k = yaw rate / speed, the yaw rate low-passed), and for curve_hold_s after it
    // (a frame without a yaw rate, the road motion not accepted, holds the last value)
    if (std::isfinite(yaw_rate_rps)) {
        if (!std::isfinite(yaw_rate_smooth_))
            yaw_rate_smooth_ = yaw_rate_rps;
        else
            yaw_rate_smooth_ += dt / (p_.yaw_rate_smoothing_s + dt) * (yaw_rate_rps - yaw_rate_smooth_);
    }
    const double r = yaw_rate_smooth_;
    const bool turning = std::isfinite(r) && (std::abs(r) > p_.max_yaw_rate_rps ||
                                              (speed_mps > 1.0 && std::abs(r) / speed_mps > p_.max_curvature_1pm));
    if (turning) last_curve_t_ = t_s;
    const bool straight = !(std::isfinite(last_curve_t_) && t_s - last_curve_t_ <= p_.curve_hold_s);

    // from scratch a believed model only (paint along both ego boundaries, lanes.evidence_min): on an unmarked road
    // the lane stage assembles "lanes" from vehicle sides, and the first measurement is the estimate
    const bool measured = lanes.valid && (lanes.certain || !p_.from_scratch) && lanes.ego_left.observed &&
                          lanes.ego_right.observed &&
                          std::isfinite(lanes.vanishing_point.x) && std::isfinite(lanes.vanishing_point.y);
    if (!measured) {
        last_offset_m_ = NAN;
        return;
    }
    const double vh = lanes.vanishing_point.y, uvp = lanes.vanishing_point.x;
    // two rows of the boundaries below the horizon: the lines' lower ends and halfway up to the horizon
    const double v1 = std::max(lanes.ego_left.bottom.y, lanes.ego_right.bottom.y);
    const double v2 = 0.5 * (v1 + vh);
    const double w1 = lanes.lane_width_px(float(v1)), w2 = lanes.lane_width_px(float(v2));
    if (!(v1 - vh > 20.0) || !(w1 > w2) || !(w2 > 0)) return;
    // lateral offset of the lane centre from the image axis, in metres at row v1 (scale W / w1)
    const double centre = 0.5 * (lanes.ego_left.x_at(float(v1)) + lanes.ego_right.x_at(float(v1)));
    const double offset_m = (centre - cfg_.cx) * p_.road.lane_width_m / w1;
    // The lateral rate. From scratch: the least-squares slope of the offset over the last lateral_rate_window_s (one
    // frame's offset jitters by a few cm with the marking edges: frame to frame at 20 fps that reads 1-2 m/s, and on
    // the real lane clips it let 0-2 frames of 20 through). Otherwise frame to frame, as the synthetic suite was
    // measured with.
    offsets_.emplace_back(t_s, offset_m);
    while (offsets_.front().first < t_s - p_.lateral_rate_window_s) offsets_.pop_front();
    const bool steady_lane =
        p_.from_scratch ? offsets_.size() >= 3 && t_s - offsets_.front().first >= 0.5 * p_.lateral_rate_window_s &&
                              std::abs(slope(offsets_)) <= p_.max_lateral_rate_mps
                        : std::isfinite(last_offset_m_) && dt > 0 &&
                              std::abs(offset_m - last_offset_m_) / dt <= p_.max_lateral_rate_mps;
    last_offset_m_ = offset_m;
    // From scratch the pitch and height are measured in every such frame (below); otherwise only in a steady lane on
    // a straight road, as the yaw.
    if (!p_.from_scratch && (!steady_lane || !straight)) return;

    const double pitch = std::atan((cfg_.cy - vh) / cfg_.fy) / kDeg;
    const double yaw = std::atan((cfg_.cx - uvp) / cfg_.fx) / kDeg;
    const double a = (w1 - w2) / (v1 - v2);  // px of lane width per row
    const double h = cfg_.fx * p_.road.lane_width_m * std::cos(pitch * kDeg) / (cfg_.fy * a);
    const double r_ang = p_.angle_noise_deg * p_.angle_noise_deg;
    const double prior_ang = p_.prior_sigma_deg * p_.prior_sigma_deg;
    const int n = p_.reacquire_after;
    // The pitch (vanishing row) and the height (lane width against the row): a lane change turns the car against the
    // lane and a curve bends the boundaries sideways, which moves the vanishing column (the yaw), not its row.
    bool used = pitch_.update(pitch, r_ang, p_.gate_sigma, n, prior_ang);
    used |= height_.update(h / cfg_.height_m, p_.height_noise * p_.height_noise, p_.gate_sigma, n,
                           p_.prior_sigma_height * p_.prior_sigma_height);
    if (steady_lane && straight) used |= yaw_update(yaw, assumed, road, settled, speed_mps, dt);
    clamp_angles();
    height_.x = std::clamp(height_.x, 1.0 - p_.max_height_dev, 1.0 + p_.max_height_dev);
    updates_ += used ? 1 : 0;
    const double conv = p_.converged_sigma_deg * p_.converged_sigma_deg;
    if (!anchored_ && pitch_.var <= conv && yaw_.var <= conv) {  // converged: the guard is centred here for good
        anchored_ = true;
        anchor_pitch_ = pitch_.x;
        anchor_yaw_ = yaw_.x;
    }
}

// The yaw from the lanes and the road's motion, and the road motion's pitch and height: only on a straight road
// in a steady lane.
bool SelfCalibration::yaw_update(double yaw, const CameraParams &assumed, const RoadMotion &road,
                                 bool settled, double speed_mps, double dt) {
    const double r_ang = p_.angle_noise_deg * p_.angle_noise_deg;
    const double prior_ang = p_.prior_sigma_deg * p_.prior_sigma_deg;
    const int n = p_.reacquire_after;
    bool used = yaw_.update(yaw, r_ang, p_.gate_sigma, n, prior_ang);
    if (p_.road_motion && road.state == RoadMotion::State::kAccepted) {
        const cv::Vec3d t = road_motion_translation(road.H, assumed);  // m, level axes of the assumed mounting
        if (t[2] > 0.2 && std::isfinite(t[0])) {
            const double yaw_motion = assumed.yaw_deg - std::atan2(t[0], t[2]) / kDeg;
            used |= yaw_.update(yaw_motion, p_.motion_yaw_noise_deg * p_.motion_yaw_noise_deg, p_.gate_sigma, n,
                                prior_ang);
        }
    }
    // pitch and height from the road plane's motion, once the estimate has converged: the fit is linearised
    // around the estimated mounting and biased while that is still off (measured: from 2 deg / 15 % off it
    // slowed the convergence from 0.1 to 1.2 s and pulled the pitch 0.19 deg away on the way)
    if (settled && road.state == RoadMotion::State::kAccepted && road.tilt_ok && road.tilt_travel_m > 0.2) {
        const double pitch_motion = assumed.pitch_deg + road.tilt_rad / kDeg;
        // travel_fit / h_assumed = travel / h: h = h_assumed * speed * dt / travel_fit
        const double h_motion = assumed.height_m * speed_mps * dt / road.tilt_travel_m;
        if (p_.motion_pitch)
            used |= pitch_.update(pitch_motion, p_.motion_pitch_noise_deg * p_.motion_pitch_noise_deg, p_.gate_sigma,
                                  n, prior_ang);
        if (p_.motion_height && speed_mps > 1.0 && dt > 0)
            used |= height_.update(h_motion / cfg_.height_m, p_.motion_height_noise * p_.motion_height_noise,
                                   p_.gate_sigma, n, p_.prior_sigma_height * p_.prior_sigma_height);
    }
    return used;
}

void SelfCalibration::clamp_angles() {
    if (!p_.from_scratch) {
        pitch_.x = std::clamp(pitch_.x, cfg_.pitch_deg - p_.max_pitch_dev_deg, cfg_.pitch_deg + p_.max_pitch_dev_deg);
        yaw_.x = std::clamp(yaw_.x, cfg_.yaw_deg - p_.max_yaw_dev_deg, cfg_.yaw_deg + p_.max_yaw_dev_deg);
        return;
    }
    double plo = p_.pitch_min_deg, phi = p_.pitch_max_deg, ylo = -p_.yaw_max_abs_deg, yhi = p_.yaw_max_abs_deg;
    if (anchored_) {
        plo = std::max(plo, anchor_pitch_ - p_.max_pitch_dev_deg);
        phi = std::min(phi, anchor_pitch_ + p_.max_pitch_dev_deg);
        ylo = std::max(ylo, anchor_yaw_ - p_.max_yaw_dev_deg);
        yhi = std::min(yhi, anchor_yaw_ + p_.max_yaw_dev_deg);
    }
    pitch_.x = std::clamp(pitch_.x, plo, std::max(plo, phi));
    yaw_.x = std::clamp(yaw_.x, ylo, std::max(ylo, yhi));
}

std::pair<double, double> SelfCalibration::search_window() const {
    const double s = p_.search_sigmas * std::sqrt(pitch_.var);
    const double lo = std::max(p_.pitch_min_deg, pitch_.x - s), hi = std::min(p_.pitch_max_deg, pitch_.x + s);
    return {0.5 * (lo + hi), 0.5 * std::max(0.0, hi - lo)};
}

CameraParams SelfCalibration::camera() const {
    CameraParams c = cfg_;
    if (!p_.enabled) return c;
    c.pitch_deg = pitch_.x;
    c.yaw_deg = yaw_.x;
    c.height_m = cfg_.height_m * height_.x;
    return c;
}

CalibrationEstimate SelfCalibration::estimate() const {
    CalibrationEstimate e;
    const CameraParams c = camera();
    e.active = p_.enabled;
    e.pitch_deg = c.pitch_deg;
    e.yaw_deg = c.yaw_deg;
    e.height_m = c.height_m;
    e.pitch_sigma_deg = p_.enabled ? std::sqrt(pitch_.var) : 0.0;
    e.yaw_sigma_deg = p_.enabled ? std::sqrt(yaw_.var) : 0.0;
    e.height_sigma_m = p_.enabled ? cfg_.height_m * std::sqrt(height_.var) : 0.0;
    e.updates = updates_;
    if (!p_.enabled) {
        e.state = CalibrationState::kOff;
    } else if ((p_.from_scratch ? at_bound(pitch_.x, p_.pitch_min_deg, p_.pitch_max_deg) ||
                                      at_bound(yaw_.x, -p_.yaw_max_abs_deg, p_.yaw_max_abs_deg) ||
                                      (anchored_ && (std::abs(pitch_.x - anchor_pitch_) >= p_.max_pitch_dev_deg - 1e-9 ||
                                                     std::abs(yaw_.x - anchor_yaw_) >= p_.max_yaw_dev_deg - 1e-9))
                                    : std::abs(pitch_.x - cfg_.pitch_deg) >= p_.max_pitch_dev_deg ||
                                      std::abs(yaw_.x - cfg_.yaw_deg) >= p_.max_yaw_dev_deg) ||
               std::abs(height_.x - 1.0) >= p_.max_height_dev) {
        e.state = CalibrationState::kAtLimit;  // clamped there by update()
    } else if (e.pitch_sigma_deg <= p_.converged_sigma_deg && e.yaw_sigma_deg <= p_.converged_sigma_deg &&
               std::sqrt(height_.var) <= p_.converged_sigma_height) {
        e.state = CalibrationState::kConverged;
    } else {
        e.state = CalibrationState::kLearning;
    }
    return e;
}

} // namespace hw
