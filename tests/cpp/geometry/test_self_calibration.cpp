// Self-calibration: lanes seen by a camera mounted otherwise than configured pull the estimate of pitch, yaw and
// height to the true mounting, its uncertainties shrink to "converged", and frames on a curve are not used.
#include "../road_scene.hpp"
#include "geometry/self_calibration.hpp"

#include <doctest/doctest.h>

TEST_CASE("self-calibration converges to the mounting the lanes show") {
    hw::CameraParams configured;  // pitch 1 deg, yaw 0, 1.3 m
    hw::CameraParams truth = configured;
    truth.pitch_deg = 2.2;
    truth.yaw_deg = -1.0;
    truth.height_m = 1.4;
    hw::SelfCalibrationParams p;
    hw::SelfCalibration sc(p, configured);
    const hw::LaneModel lanes = hw_test::ego_lane(truth, 3.6, 6.0, 40.0);
    double first_sigma = NAN;
    for (int k = 0; k < 100; ++k) {
        sc.update(lanes, 25.0, 0.0, k * 0.05);
        if (k == 0) first_sigma = sc.estimate().pitch_sigma_deg;
    }
    const hw::CalibrationEstimate e = sc.estimate();
    CHECK(std::abs(e.pitch_deg - 2.2) < 0.05);
    CHECK(std::abs(e.yaw_deg - (-1.0)) < 0.05);
    CHECK(std::abs(e.height_m - 1.4) < 0.03);
    CHECK(e.pitch_sigma_deg < first_sigma);
    CHECK(e.state == hw::CalibrationState::kConverged);
    CHECK(e.updates >= 90);
    CHECK(sc.camera().pitch_deg == doctest::Approx(e.pitch_deg));
}

TEST_CASE("self-calibration takes no measurement on a curve, and none while off") {
    hw::CameraParams configured, truth;
    truth.pitch_deg = 2.2;
    hw::SelfCalibrationParams p;
    hw::SelfCalibration curving(p, configured);
    const hw::LaneModel lanes = hw_test::ego_lane(truth, 3.6, 6.0, 40.0);
    for (int k = 0; k < 40; ++k) curving.update(lanes, 25.0, 0.1, k * 0.05);  // 0.1 rad/s: a 250 m radius
    CHECK(curving.estimate().updates == 0);
    CHECK(curving.camera().pitch_deg == doctest::Approx(1.0));
    p.enabled = false;
    hw::SelfCalibration off(p, configured);
    for (int k = 0; k < 40; ++k) off.update(lanes, 25.0, 0.0, k * 0.05);
    CHECK(off.estimate().state == hw::CalibrationState::kOff);
    CHECK(off.camera().pitch_deg == doctest::Approx(1.0));
}
