// phd/vehicle_ukf.hpp - one vehicle's position and velocity on the road by the UKF (paper 004, eq. 16-21).
//
// State x = [X lateral, Z range, dX/dt, dZ/dt] (m, m/s). Transition, constant velocity (eq. 19):
//     x' = F x,  F = [1 0 dt 0; 0 1 0 dt; 0 0 1 0; 0 0 0 1],
//     Q = white acceleration per axis: q [dt^3/3 dt^2/2; dt^2/2 dt] with q = sigma_a^2.
// Observation (eq. 16-18): the vehicle's contact point, bottom centre of its rear face, through the
// pinhole camera with its pitch (from the horizon row) and yaw: z = (u, v) = project_road_point(X, Z)
// (geometry/flat_road.hpp), R = sigma^2 I in px^2. The UKF carries the observation's curvature
// (dv/dZ = -fy h / Z^2) over the range uncertainty instead of linearising it.
// Second observation, the image expansion of the vehicle's feature cloud between two frames dt apart: a
// rigid face at range Z grows by s = Z(t - dt) / Z(t), so e = (s - 1) / dt = -(dZ/dt) / Z (1/s), with
// 1-sigma from the spread of the features' distance ratios. It carries the range rate without any pixel
// offset of the contact row (a bottom edge 1 px low biases range and rate alike; the scale does not).
#pragma once

#include "base/params.hpp"
#include "geometry/camera.hpp"
#include "track/phd/ukf.hpp"

#include <opencv2/core.hpp>

namespace hw {

struct VehicleUkfParams {
    UkfParams sigma;                   // alpha, beta, kappa
    double accel_sigma_range_mps2 = 1.5;    // m/s^2; white-acceleration noise along the range
    double accel_sigma_lateral_mps2 = 1.5;  // m/s^2; ... across
    double init_rate_sigma_mps = 20.0;      // m/s; 1-sigma of a new vehicle's relative velocity
    double init_row_sigma_px = 2.0;         // px; 1-sigma of the first contact row (sets the first range sigma)

    void bind(ParamMap &m);
};

class VehicleUkf {
public:
    // Starts at the road point under pixel (u, v) with the given horizon row.
    VehicleUkf(const VehicleUkfParams &p, const CameraParams &cam, double u, double v, double horizon_row);
    // Starts at a known state (tests).
    VehicleUkf(const VehicleUkfParams &p, const CameraParams &cam, const Eigen::Vector4d &x0, const Eigen::Matrix4d &P0);

    void predict(double dt);
    // The contact point (u, v) measured with 1-sigma `sigma_px`; false if it was not usable.
    bool update(const cv::Point2d &uv, double sigma_px, double horizon_row);
    // How far the row of a contact point (u, v) measured with 1-sigma `sigma_px` lies from the row the state
    // predicts, in sigmas of the row's innovation (state and measurement); NaN if it cannot be computed. The row
    // carries the range; the column (lateral) is left out: a box cut by the image's side moves its centre.
    double contact_row_sigmas(const cv::Point2d &uv, double sigma_px, double horizon_row) const;
    // The expansion rate e = (s - 1) / dt measured with 1-sigma `sigma_per_s`; false if not usable.
    bool update_expansion(double e_per_s, double sigma_per_s);
    // The camera changed (self-calibration's estimate). The same pixels put every road point height'/height as far
    // from the camera's foot, so the distances, speeds and their covariance are rescaled by that ratio; a changed
    // pitch or yaw acts through the next observations.
    void set_camera(const CameraParams &cam);
    // The contact point the state predicts.
    cv::Point2d predicted_contact(double horizon_row) const;

    double lateral() const { return f_.x()(0); }
    double range() const { return f_.x()(1); }
    double lateral_rate() const { return f_.x()(2); }
    double range_rate() const { return f_.x()(3); }
    double range_sigma() const { return std::sqrt(std::max(0.0, f_.P()(1, 1))); }
    double range_rate_sigma() const { return std::sqrt(std::max(0.0, f_.P()(3, 3))); }
    const Ukf &filter() const { return f_; }

    static Ukf::Vec transition(const Ukf::Vec &x, double dt);  // eq. 19
    static Ukf::Mat process_noise(double dt, double sigma_x, double sigma_z);

private:
    Ukf::Observation contact_observation(double horizon_row) const;  // eq. 16-18: (X, Z) -> (u, v)

    VehicleUkfParams p_;
    CameraParams cam_;
    Ukf f_;
};

} // namespace hw
