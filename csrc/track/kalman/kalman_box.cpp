#include "track/kalman/kalman_box.hpp"

#include <Eigen/Dense>

#include <cmath>
#include <stdexcept>

namespace hw {

namespace {

KalmanBox::Mat3 measurement_noise(double sx, double sy) {
    KalmanBox::Mat3 R = KalmanBox::Mat3::Zero();
    R(0, 0) = sx * sx;
    R(1, 1) = sy * sy;
    R(2, 2) = sx * sx;
    return R;
}

} // namespace

KalmanBox::KalmanBox(const Vec3 &z, double sigma_pos_px, double sigma_vel_px_s) {
    if (!z.allFinite()) throw std::invalid_argument("KalmanBox: initial measurement not finite");
    if (!(sigma_pos_px > 0.0) || !(sigma_vel_px_s > 0.0))
        throw std::invalid_argument("KalmanBox: initial standard deviations must be positive");
    x_ << z, 0.0, 0.0, 0.0;
    P_.setZero();
    for (int i = 0; i < 3; ++i) {
        P_(i, i) = sigma_pos_px * sigma_pos_px;
        P_(i + 3, i + 3) = sigma_vel_px_s * sigma_vel_px_s;
    }
}

void KalmanBox::predict(double dt, double accel_x, double accel_y, double p_max, double p_zero, const Vec3 &known) {
    if (!(dt >= 0.0) || !std::isfinite(dt)) throw std::invalid_argument("KalmanBox::predict: dt must be >= 0");
    if (!known.allFinite()) throw std::invalid_argument("KalmanBox::predict: known acceleration not finite");
    // x' = F x + B a
    Mat6 F = Mat6::Identity();
    for (int i = 0; i < 3; ++i) F(i, i + 3) = dt;
    x_ = F * x_;
    x_.head<3>() += 0.5 * dt * dt * known;
    x_.tail<3>() += dt * known;
    // sigma_u^2 = A^2/3 (1 + 4 P_max - P_0), per axis; Q from piecewise-constant acceleration.
    const double shape = (1.0 + 4.0 * p_max - p_zero) / 3.0;
    const double var[3] = {accel_x * accel_x * shape, accel_y * accel_y * shape, accel_x * accel_x * shape};
    Mat6 Q = Mat6::Zero();
    const double dt2 = dt * dt;
    for (int i = 0; i < 3; ++i) {
        Q(i, i) = var[i] * dt2 * dt2 / 4.0;
        Q(i, i + 3) = Q(i + 3, i) = var[i] * dt2 * dt / 2.0;
        Q(i + 3, i + 3) = var[i] * dt2;
    }
    // P' = F P F^T + Q
    P_ = F * P_ * F.transpose() + Q;
}

KalmanBox::Mat3 KalmanBox::innovation_cov(double sx, double sy) const {
    return P_.topLeftCorner<3, 3>() + measurement_noise(sx, sy);
}

void KalmanBox::update(const Vec3 &z, double sx, double sy) {
    if (!z.allFinite()) throw std::invalid_argument("KalmanBox::update: measurement not finite");
    // y = z - H x;  S = H P H^T + R;  K = P H^T S^-1;  x += K y;  P = (I - K H) P (I - K H)^T + K R K^T
    const Mat3 R = measurement_noise(sx, sy);
    const Vec3 y = z - x_.head<3>();
    const Mat3 S = P_.topLeftCorner<3, 3>() + R;
    const Eigen::Matrix<double, 6, 3> K = P_.leftCols<3>() * S.inverse();
    x_ += K * y;
    Eigen::Matrix<double, 6, 6> IKH = Mat6::Identity();
    IKH.leftCols<3>() -= K;
    P_ = IKH * P_ * IKH.transpose() + K * R * K.transpose();  // Joseph form: stays symmetric PSD
}

} // namespace hw
