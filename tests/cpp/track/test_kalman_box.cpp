// The thesis's Kalman filter on a vehicle's bottom corners: the Singer process noise is the closed form, the
// covariance shrinks with each measurement, and a box moving at constant velocity is followed with its velocity.
#include "track/kalman/kalman_box.hpp"

#include <doctest/doctest.h>

#include <random>

using hw::KalmanBox;

TEST_CASE("prediction: constant velocity, process noise sigma_u^2 = A^2/3 (1 + 4 P_max - P_0)") {
    KalmanBox kb(KalmanBox::Vec3(100, 300, 160), 2.0, 50.0);
    const double dt = 0.05, A = 200.0, pmax = 0.1, p0 = 0.2;
    const KalmanBox::Mat6 P0 = kb.cov();
    kb.predict(dt, A, A, pmax, p0);
    const double su2 = A * A / 3 * (1 + 4 * pmax - p0);
    // position variance: P + dt^2 Pv + sigma_u^2 dt^4 / 4 (no initial correlation)
    CHECK(kb.cov()(0, 0) == doctest::Approx(P0(0, 0) + dt * dt * P0(3, 3) + su2 * std::pow(dt, 4) / 4).epsilon(1e-9));
    CHECK(kb.cov()(3, 3) == doctest::Approx(P0(3, 3) + su2 * dt * dt).epsilon(1e-9));
    CHECK(kb.cov()(0, 3) == doctest::Approx(dt * P0(3, 3) + su2 * std::pow(dt, 3) / 2).epsilon(1e-9));
    // a known acceleration of the columns moves them by a dt^2 / 2
    KalmanBox moved(KalmanBox::Vec3(100, 300, 160), 2.0, 50.0);
    moved.predict(dt, A, A, pmax, p0, KalmanBox::Vec3(40, 0, 40));
    CHECK(moved.state()(0) == doctest::Approx(100 + 40 * dt * dt / 2));
    CHECK(moved.state()(3) == doctest::Approx(40 * dt));
}

TEST_CASE("measurements shrink the covariance and the velocity is found") {
    std::mt19937 rng(2);
    std::normal_distribution<double> noise(0.0, 1.0);
    KalmanBox kb(KalmanBox::Vec3(100, 300, 160), 2.0, 100.0);
    double last = kb.cov()(0, 0);
    const double dt = 1.0 / 30, vx = 30.0, vy = 12.0;
    for (int k = 1; k <= 90; ++k) {
        kb.predict(dt, 100.0, 100.0, 0.0, 0.0);
        const double before = kb.cov()(0, 0);
        kb.update(KalmanBox::Vec3(100 + vx * k * dt + noise(rng), 300 + vy * k * dt + noise(rng),
                                  160 + vx * k * dt + noise(rng)), 1.0, 1.0);
        CHECK(kb.cov()(0, 0) < before);  // every update is informative
        if (k <= 3) {
            CHECK(kb.cov()(0, 0) < last);
            last = kb.cov()(0, 0);
        }
    }
    // 3 s of 1 px noise: the velocity within 5 px/s, the corners within 1 px
    CHECK(std::abs(kb.state()(3) - vx) < 5.0);
    CHECK(std::abs(kb.state()(4) - vy) < 5.0);
    CHECK(std::abs(kb.state()(0) - (100 + vx * 3.0)) < 1.0);
    const KalmanBox::Mat3 S = kb.innovation_cov(1.0, 1.0);
    CHECK(S(0, 0) == doctest::Approx(kb.cov()(0, 0) + 1.0));
}
