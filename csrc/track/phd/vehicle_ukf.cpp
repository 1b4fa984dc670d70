#include "track/phd/vehicle_ukf.hpp"

#include "geometry/flat_road.hpp"

#include <cmath>

namespace hw {

void VehicleUkfParams::bind(ParamMap &m) {
    sigma.bind(m);
    m.add("accel_sigma_range_mps2", accel_sigma_range_mps2, 0.01, 50.0,
          "m/s^2; white-acceleration process noise along the range (Q of eq. 20; docs/tracking.md)");
    m.add("accel_sigma_lateral_mps2", accel_sigma_lateral_mps2, 0.01, 50.0,
          "m/s^2; white-acceleration process noise across (lane changes)");
    m.add("init_rate_sigma_mps", init_rate_sigma_mps, 0.1, 100.0,
          "m/s; 1-sigma of a new vehicle's relative velocity (unknown until it has been seen to move): a car stopped "
          "ahead closes at the ego speed, 28 m/s at 100 km/h");
    m.add("init_row_sigma_px", init_row_sigma_px, 0.1, 50.0,
          "px; 1-sigma of a new vehicle's contact row and column; the first range sigma is Z^2/(fy h) times it");
}

namespace {

Eigen::Matrix4d initial_cov(const VehicleUkfParams &p, const CameraParams &cam, double z) {
    const double sz = range_sigma(cam, z, p.init_row_sigma_px), sx = z / cam.fx * p.init_row_sigma_px + 0.5;
    const double sr = p.init_rate_sigma_mps;
    return Eigen::Vector4d(sx * sx, sz * sz, sr * sr, sr * sr).asDiagonal();
}

Eigen::Vector4d initial_state(const CameraParams &cam, double u, double v, double horizon_row) {
    const RoadPoint rp = road_point(cam, u, v, horizon_row);
    if (!rp.valid()) throw std::invalid_argument("VehicleUkf: contact point at or above the horizon");
    return {rp.x_m, rp.z_m, 0.0, 0.0};
}

} // namespace

VehicleUkf::VehicleUkf(const VehicleUkfParams &p, const CameraParams &cam, double u, double v, double horizon_row)
    : VehicleUkf(p, cam, initial_state(cam, u, v, horizon_row),
                 initial_cov(p, cam, initial_state(cam, u, v, horizon_row)(1))) {}

VehicleUkf::VehicleUkf(const VehicleUkfParams &p, const CameraParams &cam, const Eigen::Vector4d &x0,
                       const Eigen::Matrix4d &P0)
    : p_(p), cam_(cam), f_(p.sigma, x0, P0) {}

Ukf::Vec VehicleUkf::transition(const Ukf::Vec &x, double dt) {
    Ukf::Vec y = x;
    y(0) += dt * x(2);
    y(1) += dt * x(3);
    return y;
}

Ukf::Mat VehicleUkf::process_noise(double dt, double sigma_x, double sigma_z) {
    Ukf::Mat Q = Ukf::Mat::Zero(4, 4);
    const double a = dt * dt * dt / 3.0, b = dt * dt / 2.0;
    const double qx = sigma_x * sigma_x, qz = sigma_z * sigma_z;
    Q(0, 0) = a * qx; Q(0, 2) = Q(2, 0) = b * qx; Q(2, 2) = dt * qx;
    Q(1, 1) = a * qz; Q(1, 3) = Q(3, 1) = b * qz; Q(3, 3) = dt * qz;
    return Q;
}

void VehicleUkf::predict(double dt) {
    if (dt <= 0.0) return;
    f_.predict(transition, dt, process_noise(dt, p_.accel_sigma_lateral_mps2, p_.accel_sigma_range_mps2));
}

Ukf::Observation VehicleUkf::contact_observation(double horizon_row) const {
    const CameraParams cam = cam_;
    return [cam, horizon_row](const Ukf::Vec &x) {
        const cv::Point2d p = project_road_point(cam, x(0), x(1), horizon_row);
        return Ukf::Vec(Eigen::Vector2d(p.x, p.y));
    };
}

bool VehicleUkf::update(const cv::Point2d &uv, double sigma_px, double horizon_row) {
    if (!std::isfinite(uv.x) || !std::isfinite(uv.y) || !(sigma_px > 0.0)) return false;
    const Ukf::Mat R = Eigen::Matrix2d::Identity() * sigma_px * sigma_px;
    return f_.update(contact_observation(horizon_row), Eigen::Vector2d(uv.x, uv.y), R);
}

double VehicleUkf::contact_row_sigmas(const cv::Point2d &uv, double sigma_px, double horizon_row) const {
    if (!std::isfinite(uv.x) || !std::isfinite(uv.y) || !(sigma_px > 0.0)) return NAN;
    const Ukf::Mat R = Eigen::Matrix2d::Identity() * sigma_px * sigma_px;
    Ukf::Vec nu;
    Ukf::Mat S;
    if (!f_.innovation(contact_observation(horizon_row), Eigen::Vector2d(uv.x, uv.y), R, nu, S)) return NAN;
    return S(1, 1) > 0.0 ? std::abs(nu(1)) / std::sqrt(S(1, 1)) : NAN;
}

bool VehicleUkf::update_expansion(double e_per_s, double sigma_per_s) {
    if (!std::isfinite(e_per_s) || !(sigma_per_s > 0.0)) return false;
    const auto h = [](const Ukf::Vec &x) { return Ukf::Vec::Constant(1, x(1) > 0.1 ? -x(3) / x(1) : NAN); };
    const Ukf::Mat R = Ukf::Mat::Constant(1, 1, sigma_per_s * sigma_per_s);
    return f_.update(h, Ukf::Vec::Constant(1, e_per_s), R);
}

void VehicleUkf::set_camera(const CameraParams &cam) {
    const double k = cam.height_m / cam_.height_m;
    if (std::isfinite(k) && k > 0.0 && k != 1.0) {
        Ukf::Vec &x = f_.x();
        x(0) = cam.lateral_m + k * (x(0) - cam_.lateral_m);
        x.tail(3) *= k;
        f_.P() *= k * k;
    }
    cam_ = cam;
}

cv::Point2d VehicleUkf::predicted_contact(double horizon_row) const {
    return project_road_point(cam_, f_.x()(0), f_.x()(1), horizon_row);
}

} // namespace hw
