// homography_kalman.hpp - the road-plane homography between consecutive frames, filtered
// (paper 000, section II-B).
//
// State: the nine entries of H (previous -> current frame), expressed in road-band coordinates:
// H_n = T H T^-1 scaled to H_n(2,2) = 1, where T moves the middle of the road band (the rows between
// the horizon and the bottom, centre column) to the origin and divides by half the image width.
// The entries are then dimensionless and comparable, and since the road points lie within about
// +-1 of the origin, ||H_1 - H_2||_2 is close to the largest disagreement of the two homographies
// on the road in half-widths: the gate reads as pixels (gate * width / 2). (In pixel coordinates the
// translation entries would dominate the norm; in plain normalised camera coordinates the entries
// that only matter far above the road would.)
// Constant-state Kalman filter, the same for every entry:
//     predict   x_k^- = x_{k-1}          P^- = P + Q          (Q = q I)
//     gate      ||H_meas - H_pred||_2 < t_a   (largest singular value)
//     update    K = P^- / (P^- + R)   x = x^- + K (z - x^-)   P = (1 - K) P^-   (R = r I)
// A measurement outside the gate is not used and the prediction carries on; coast_frames counts
// the frames since a measurement was last accepted. The filter starts from two consecutive
// measurements that agree within the gate (before it has started, the last measurement serves as
// the prediction that guides the next frame's features). Because a constant-state filter never leaves a wrong
// state by itself (every good measurement is then gated out), it also restarts from the newest
// measurement when restart_agreeing consecutive rejected measurements agree with each other within
// the gate (they, not the state, describe the road), and it is dropped after max_coast_frames.
//
// Ego speed (CAN), when known for this frame and the previous one, informs the prediction: the
// travel part of H is replaced by this frame's, x^- = H_{k-1} G(s_{k-1})^-1 G(s_k), with
// G(s) = K R_c (I - t n^T / h) R_c^T K^-1 the road homography of a forward travel s = v dt at the
// static mounting R_c (pitch, yaw), n = (0, 1, 0), t = (0, 0, s) in level-camera axes.
#pragma once

#include "base/params.hpp"
#include "geometry/camera.hpp"

#include <opencv2/core.hpp>

#include <cmath>

namespace hw {

struct HomographyKalmanParams {
    double q = 1e-5;              // process noise variance per entry (paper: 1e-6)
    double r = 1e-5;              // measurement noise variance per entry (paper: 1e-3)
    double gate = 0.05;           // t_a on the 2-norm of H_meas - H_pred (road-band coordinates)
    int max_coast_frames = 15;    // frames on the prediction alone before the filter is lost
    int restart_agreeing = 3;     // consecutive rejected measurements agreeing with each other restart the filter
    bool use_ego_speed = true;    // CAN speed informs the prediction when known

    void bind(ParamMap &m);
};

// Road homography of a forward travel of s metres for the camera's static mounting, in pixels,
// previous -> current.
cv::Matx33d travel_homography(const CameraParams &cam, double s_m);

// The road-band normalisation T of the filter state (see above).
cv::Matx33d road_band_normaliser(const CameraParams &cam);

// Largest singular value of a 3x3 matrix.
double spectral_norm(const cv::Matx33d &A);

class HomographyKalman {
public:
    enum class Status { kNone, kAccepted, kRejected, kNoMeasurement };

    HomographyKalman(const HomographyKalmanParams &p, const CameraParams &cam);

    // Time update for a new frame; step_m = ego travel since the previous frame (NaN = unknown).
    void predict(double step_m);
    // Without a state or a previous measurement, a guess of this frame's travel (found from the images)
    // stands in for the ego speed as the prediction.
    void guess_travel(double step_m);
    bool guessed() const { return guessed_; }  // the prediction is only such a guess (searched, not measured)
    // Measurement update (pixel coordinates); null = no measurement this frame.
    Status update(const cv::Matx33d *H_meas_px);

    bool valid() const { return initialised_; }             // an estimate exists (measured or coasting)
    // predicted_px() means something: a state, a previous measurement or the ego speed
    bool has_prediction() const { return initialised_ || agreeing_ > 0 || std::isfinite(step_); }
    cv::Matx33d H_px() const;                              // current estimate, pixels, prev -> cur
    cv::Matx33d predicted_px() const;                      // last prediction, pixels (identity if none)
    int coast_frames() const { return coast_; }
    double last_distance() const { return distance_; }     // ||H_meas - H_pred||_2 of the last measurement
    void reset();

private:
    cv::Matx33d to_normalised(const cv::Matx33d &H_px) const;
    cv::Matx33d to_pixels(const cv::Matx33d &H_n) const;

    HomographyKalmanParams p_;
    cv::Matx33d T_, Tinv_;
    CameraParams cam_;
    bool initialised_ = false;
    cv::Matx33d x_ = cv::Matx33d::eye();     // state (normalised)
    cv::Matx33d pred_ = cv::Matx33d::eye();  // x^- of this frame
    double P_ = 0.0;                          // variance of every entry
    double step_ = NAN, step_prev_ = NAN;     // ego travel of this and the previous frame
    int agreeing_ = 0;                        // consecutive measurements agreeing with each other, not with x
    bool guessed_ = false;                    // pred_ came from guess_travel()
    cv::Matx33d candidate_;                   // the last of them
    int coast_ = 0;
    double distance_ = NAN;
};

} // namespace hw
