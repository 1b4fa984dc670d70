// The road-plane homography: the normalised DLT recovers a known homography from exact correspondences, its
// trimming pass drops a far wrong match that would spoil the fit, and the Kalman filter on the homography
// starts from two agreeing measurements, gates out one far from its prediction and coasts on the prediction.
#include "geometry/homography_dlt.hpp"
#include "geometry/homography_kalman.hpp"

#include <doctest/doctest.h>

#include <random>
#include <vector>

namespace {

cv::Point2f apply(const cv::Matx33d &H, cv::Point2f p) {
    const cv::Vec3d q = H * cv::Vec3d(p.x, p.y, 1.0);
    return {float(q[0] / q[2]), float(q[1] / q[2])};
}

// Road points of the lower image (rows 260-470) and where the travel homography of `s_m` puts them.
void road_points(const cv::Matx33d &H, std::vector<cv::Point2f> &from, std::vector<cv::Point2f> &to, int n = 40) {
    std::mt19937 rng(7);
    std::uniform_real_distribution<float> u(60.f, 580.f), v(260.f, 470.f);
    for (int i = 0; i < n; ++i) {
        from.push_back({u(rng), v(rng)});
        to.push_back(apply(H, from.back()));
    }
}

double max_transfer(const cv::Matx33d &A, const cv::Matx33d &B, const std::vector<cv::Point2f> &pts) {
    double worst = 0;
    for (const auto &p : pts) worst = std::max(worst, double(cv::norm(apply(A, p) - apply(B, p))));
    return worst;
}

} // namespace

TEST_CASE("normalised DLT recovers the homography of exact correspondences") {
    const cv::Matx33d H(1.02, 0.01, -3.0, 0.004, 1.03, -8.0, 1e-5, 4e-5, 1.0);
    std::vector<cv::Point2f> from, to;
    road_points(H, from, to);
    const cv::Matx33d E = hw::normalised_dlt(from, to);
    CHECK(E(2, 2) == doctest::Approx(1.0));
    CHECK(max_transfer(E, H, from) < 1e-3);  // px, float point coordinates
    CHECK(hw::transfer_error(E, from[3], to[3]) < 1e-3);
}

TEST_CASE("the trimming pass drops a far wrong correspondence") {
    const hw::CameraParams cam;
    const cv::Matx33d H = hw::travel_homography(cam, 1.0);  // one metre forward
    std::vector<cv::Point2f> from, to;
    road_points(H, from, to);
    std::mt19937 rng(3);
    std::normal_distribution<float> noise(0.f, 0.3f);
    for (auto &p : to) p += cv::Point2f(noise(rng), noise(rng));
    to[5] += cv::Point2f(0.f, 25.f);  // a dash end matched to the next dash
    hw::DltParams p;
    p.ransac_px = 0.0;  // the DLT and its trimming alone
    const hw::HomographyFit fit = hw::fit_homography(from, to, p, &H);
    REQUIRE(fit.ok);
    CHECK(fit.used <= 39);
    CHECK(fit.rms_px < 0.6);
    CHECK(max_transfer(fit.H, H, from) < 1.0);
    // without the wrong one's removal the plain DLT is pulled by it
    CHECK(max_transfer(hw::normalised_dlt(from, to), H, from) > max_transfer(fit.H, H, from));
}

TEST_CASE("homography Kalman: starts from agreeing measurements, shrinks its variance, gates out a far one") {
    const hw::CameraParams cam;
    hw::HomographyKalmanParams p;
    p.use_ego_speed = false;
    hw::HomographyKalman kf(p, cam);
    const cv::Matx33d G = hw::travel_homography(cam, 1.0);
    std::vector<cv::Point2f> pts, unused;
    road_points(G, pts, unused);
    kf.predict(NAN);
    kf.update(&G);
    CHECK_FALSE(kf.valid());  // one measurement alone starts nothing
    kf.predict(NAN);
    CHECK(kf.update(&G) == hw::HomographyKalman::Status::kAccepted);
    REQUIRE(kf.valid());
    CHECK(max_transfer(kf.H_px(), G, pts) < 1e-6);
    // a measurement 2 m of travel off is far outside the 0.05 gate: rejected, the prediction carries on
    const cv::Matx33d far = hw::travel_homography(cam, 3.0);
    kf.predict(NAN);
    CHECK(kf.update(&far) == hw::HomographyKalman::Status::kRejected);
    CHECK(kf.last_distance() > p.gate);
    CHECK(kf.coast_frames() == 1);
    CHECK(max_transfer(kf.H_px(), G, pts) < 1e-6);
    // a slightly different one is taken, pulled towards by the Kalman gain (between the two)
    const cv::Matx33d near = hw::travel_homography(cam, 1.05);
    kf.predict(NAN);
    CHECK(kf.update(&near) == hw::HomographyKalman::Status::kAccepted);
    const double to_g = max_transfer(kf.H_px(), G, pts), to_near = max_transfer(kf.H_px(), near, pts);
    CHECK(to_g > 0.01);
    CHECK(to_near < max_transfer(G, near, pts));
    CHECK(kf.coast_frames() == 0);
    // on the prediction alone for more than max_coast_frames the filter is lost
    for (int i = 0; i <= p.max_coast_frames; ++i) {
        kf.predict(NAN);
        kf.update(nullptr);
    }
    CHECK_FALSE(kf.valid());
}

TEST_CASE("the travel homography moves a road point by the travel on the flat road") {
    const hw::CameraParams cam;
    // a road point 20 m ahead seen at row v is seen after 1 m of travel at the row of 19 m
    const double vh = cam.horizon_row();
    const cv::Point2f at20(320.f, float(vh + cam.fy * cam.height_m / 20.0));
    const cv::Point2f moved = apply(hw::travel_homography(cam, 1.0), at20);
    CHECK(moved.x == doctest::Approx(320.0).epsilon(1e-3));
    // 1 deg of pitch: the level-road approximation Z = fy h / (v - vh) is within 0.05 px here
    CHECK(moved.y == doctest::Approx(vh + cam.fy * cam.height_m / 19.0).epsilon(2e-4));
}
