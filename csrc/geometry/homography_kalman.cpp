#include "geometry/homography_kalman.hpp"

#include <cmath>

namespace hw {

void HomographyKalmanParams::bind(ParamMap &m) {
    m.add("q", q, 0.0, 1.0,
          "process noise variance of each of the nine entries of H in road-band coordinates; the paper's filter "
          "is q 1e-6 with r 1e-3 (docs/tracking.md)");
    m.add("r", r, 1e-12, 1.0,
          "measurement noise variance of each entry of a DLT homography (road-band coordinates); our measurements "
          "(pre-warped LK, ~50 points) err by ~3e-3 (median 2-norm), far less than the paper's sparse ones");
    m.add("gate", gate, 1e-6, 10.0,
          "t_a; a measured H is accepted only if the 2-norm of H_meas - H_pred (road-band coordinates) is below "
          "this; 0.05 is ~16 px at 640 px (docs/tracking.md)");
    m.add("max_coast_frames", max_coast_frames, 0, 100000,
          "frames; after this many frames without an accepted measurement the filter is lost and starts again from "
          "two agreeing measurements (the alignment of a stale prediction is worse than none)");
    m.add("restart_agreeing", restart_agreeing, 2, 1000,
          "count; this many consecutive rejected measurements that agree with each other within the gate restart "
          "the filter from the newest (a wrong state would otherwise gate out every good measurement); 3 = 0.1 s "
          "at 30 fps");
    m.add("use_ego_speed", use_ego_speed,
          "use the CAN ego speed, when known, to replace the travel part of the predicted homography");
}

cv::Matx33d road_band_normaliser(const CameraParams &cam) {
    const double s = 2.0 / cam.width;
    const double yc = 0.5 * (cam.horizon_row() + cam.height);
    return {s, 0, -s * cam.cx, 0, s, -s * yc, 0, 0, 1};
}

cv::Matx33d travel_homography(const CameraParams &cam, double s_m) {
    const double p = cam.pitch_deg * M_PI / 180.0, b = cam.yaw_deg * M_PI / 180.0;
    // Same rotation as the camera model: yaw about y, then pitch about x (pitch > 0 looks down).
    const cv::Matx33d Ryaw(std::cos(b), 0, -std::sin(b), 0, 1, 0, std::sin(b), 0, std::cos(b));
    const cv::Matx33d Rpitch(1, 0, 0, 0, std::cos(p), -std::sin(p), 0, std::sin(p), std::cos(p));
    const cv::Matx33d R = Rpitch * Ryaw;
    // Road points of the level camera satisfy n^T X = h with n = (0, 1, 0) (y down); travelling s forward,
    // X' = X - t = (I - t n^T / h) X with t = (0, 0, s).
    const cv::Matx33d T(1, 0, 0, 0, 1, 0, 0, -s_m / cam.height_m, 1);
    const cv::Matx33d K(cam.fx, 0, cam.cx, 0, cam.fy, cam.cy, 0, 0, 1);
    cv::Matx33d G = K * R * T * R.t() * K.inv();
    return G * (1.0 / G(2, 2));
}

double spectral_norm(const cv::Matx33d &A) {
    cv::Matx31d w;
    cv::SVD::compute(A, w, cv::SVD::NO_UV);
    return w(0);
}

HomographyKalman::HomographyKalman(const HomographyKalmanParams &p, const CameraParams &cam) : p_(p), cam_(cam) {
    T_ = road_band_normaliser(cam);
    Tinv_ = T_.inv();
}

void HomographyKalman::reset() {
    initialised_ = false;
    agreeing_ = 0;
    x_ = pred_ = cv::Matx33d::eye();
    P_ = 0.0;
    step_ = step_prev_ = NAN;
    coast_ = 0;
    distance_ = NAN;
}

cv::Matx33d HomographyKalman::to_normalised(const cv::Matx33d &H_px) const {
    cv::Matx33d H = T_ * H_px * Tinv_;
    return H * (1.0 / H(2, 2));
}

cv::Matx33d HomographyKalman::to_pixels(const cv::Matx33d &H_n) const {
    cv::Matx33d H = Tinv_ * H_n * T_;
    return H * (1.0 / H(2, 2));
}

cv::Matx33d HomographyKalman::H_px() const { return to_pixels(x_); }
cv::Matx33d HomographyKalman::predicted_px() const { return to_pixels(pred_); }

void HomographyKalman::predict(double step_m) {
    guessed_ = false;
    step_prev_ = step_;
    step_ = p_.use_ego_speed ? step_m : NAN;
    if (!initialised_) {
        // Without a state the best guess is the last measurement (the road moves much the same from one
        // frame to the next), else the road moving by the known travel, else not at all.
        pred_ = agreeing_ > 0 ? candidate_
                : std::isfinite(step_) ? to_normalised(travel_homography(cam_, step_)) : cv::Matx33d::eye();
        return;
    }
    // x^- = x_{k-1}, with the travel part swapped for this frame's when the ego speed is known.
    pred_ = x_;
    if (std::isfinite(step_) && std::isfinite(step_prev_)) {
        pred_ = x_ * to_normalised(travel_homography(cam_, step_prev_).inv() * travel_homography(cam_, step_));
        pred_ = pred_ * (1.0 / pred_(2, 2));
    }
    P_ += p_.q;  // P^- = P + Q
}

void HomographyKalman::guess_travel(double step_m) {
    if (initialised_ || agreeing_ > 0 || !std::isfinite(step_m)) return;
    pred_ = to_normalised(travel_homography(cam_, step_m));
    guessed_ = true;
}

HomographyKalman::Status HomographyKalman::update(const cv::Matx33d *H_meas_px) {
    distance_ = NAN;
    if (!H_meas_px) {
        agreeing_ = 0;
        if (initialised_) {
            x_ = pred_;
            if (++coast_ > p_.max_coast_frames) reset();
        }
        return Status::kNoMeasurement;
    }
    const cv::Matx33d z = to_normalised(*H_meas_px);
    // Count consecutive measurements that agree with each other (used to start and to restart).
    agreeing_ = (agreeing_ > 0 && spectral_norm(z - candidate_) < p_.gate) ? agreeing_ + 1 : 1;
    candidate_ = z;
    const int needed = initialised_ ? p_.restart_agreeing : 2;
    if (initialised_) distance_ = spectral_norm(z - pred_);
    if (initialised_ && distance_ < p_.gate) {
        const double gain = P_ / (P_ + p_.r);  // K = P^- (P^- + R)^-1
        x_ = pred_ + gain * (z - pred_);
        x_ = x_ * (1.0 / x_(2, 2));
        P_ = (1.0 - gain) * P_;
        coast_ = 0;
        agreeing_ = 0;
        return Status::kAccepted;
    }
    if (agreeing_ >= needed) {
        // (Re)start from the newest of the agreeing measurements.
        x_ = z;
        P_ = p_.r;
        initialised_ = true;
        coast_ = 0;
        agreeing_ = 0;
        return Status::kAccepted;
    }
    if (initialised_) {
        x_ = pred_;
        if (++coast_ > p_.max_coast_frames) reset();
    }
    return Status::kRejected;
}

} // namespace hw
