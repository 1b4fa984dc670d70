// kalman/kalman_box.hpp - the thesis's Kalman filter on a vehicle's two bottom corners (thesis 3.5).
//
// State x = [x1, y1, x2, vx1, vy1, vx2]: bottom-left corner (x1, y1), right corner column x2 (the
// two corners share the bottom row), and their image velocities in px/s. Constant velocity:
//     x_k = F x_{k-1} + w,    F = [I  dt I; 0  I]
// A known image acceleration a (3 components) can enter as a control input: x += [dt^2/2 I; dt I] a.
// Measurement z = [x1, y1, x2] = H x + v, H = [I 0], R = diag(sigma_x^2, sigma_y^2, sigma_x^2).
// Process noise from the bounded-acceleration model (thesis eq. 3.24, after Singer): the
// acceleration u along each axis is uniform in [-A, A] with extra probability P_max at each of +-A
// and P_0 at 0, so
//     sigma_u^2 = A^2 / 3 * (1 + 4 P_max - P_0),
// entering each (position, velocity) pair as piecewise-constant acceleration over dt:
//     Q_axis = sigma_u^2 * [dt^4/4  dt^3/2; dt^3/2  dt^2].
#pragma once

#include <Eigen/Core>

namespace hw {

class KalmanBox {
public:
    using Vec3 = Eigen::Matrix<double, 3, 1>;
    using Vec6 = Eigen::Matrix<double, 6, 1>;
    using Mat3 = Eigen::Matrix<double, 3, 3>;
    using Mat6 = Eigen::Matrix<double, 6, 6>;

    // Starts at measurement z with zero velocity; position variance sigma_pos^2, velocity sigma_vel^2.
    KalmanBox(const Vec3 &z, double sigma_pos_px, double sigma_vel_px_s);

    // Time update over dt seconds. accel_x/accel_y: the bound A of the image acceleration, px/s^2,
    // for the columns (x1, x2) and the row (y1); p_max, p_zero: the model's point probabilities;
    // known: a deterministic acceleration of [x1, y1, x2] in px/s^2 (zero for pure constant velocity).
    void predict(double dt_s, double accel_x_px_s2, double accel_y_px_s2, double p_max, double p_zero,
                 const Vec3 &known = Vec3::Zero());

    // Measurement update with z = [x1, y1, x2] and per-component standard deviations.
    void update(const Vec3 &z, double sigma_x_px, double sigma_y_px);

    // Predicted measurement H x and its innovation covariance S = H P H^T + R.
    Vec3 measurement() const { return x_.head<3>(); }
    Mat3 innovation_cov(double sigma_x_px, double sigma_y_px) const;

    const Vec6 &state() const { return x_; }
    const Mat6 &cov() const { return P_; }

private:
    Vec6 x_;
    Mat6 P_;
};

} // namespace hw
