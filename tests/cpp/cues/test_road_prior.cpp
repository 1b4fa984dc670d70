// The road prior: without lanes a vehicle's expected width at a row is the pinhole model's
// (fx / fy) W (y - y_h) / h and the scan covers road_half_width_m each side of the ego lane's centre; with a
// believed lane model the width is the lane's share W / lane width, and the scan covers the adjacent lanes.
#include "cues/road_prior.hpp"
#include "../road_scene.hpp"

#include <doctest/doctest.h>

TEST_CASE("road prior from the camera: the pinhole width and a 9 m scan each side") {
    const hw::CameraParams cam;  // 640x480, fx = fy = 700, 1.3 m, 1 deg down
    const hw::RoadPriorParams p;
    const hw::RoadPrior r = hw::make_road_prior({640, 480}, hw::LaneModel{}, cam, p);
    REQUIRE_FALSE(r.empty());
    CHECK_FALSE(r.from_lanes);
    const double yh = cam.horizon_row();
    CHECK(r.horizon_row == doctest::Approx(yh));
    // the first scanned row: a vehicle's ground row at max_range_m (120 m)
    CHECK(r.y_top == int(std::ceil(yh + 700.0 * 1.3 / 120.0)));
    CHECK(r.y_bottom == 478);
    for (int y : {r.y_top + 5, 300, 400}) {
        CHECK(r.expected_width(y) == doctest::Approx(1.8 * (y - yh) / 1.3).epsilon(1e-4));
        // 9 m each side of the centre line at the row's range: 9 / 1.8 expected widths
        const double half = 9.0 / 1.8 * r.expected_width(y);
        CHECK(std::abs(r.left(y) - std::max(1.0, 320.0 - half)) <= 1.0);
        CHECK(std::abs(r.right(y) - std::min(638.0, 320.0 + half)) <= 1.0);
    }
    // an image of twice the size: the camera scaled with it, the widths doubled
    const hw::RoadPrior big = hw::make_road_prior({1280, 960}, hw::LaneModel{}, cam, p);
    CHECK(big.expected_width(800) == doctest::Approx(2 * r.expected_width(400)).epsilon(2e-3));
}

TEST_CASE("road prior from a believed lane model: the lane's share and the adjacent lanes") {
    const hw::CameraParams cam;
    const hw::LaneModel m = hw_test::ego_lane(cam, 3.2);  // a 3.2 m lane
    const hw::RoadPriorParams p;
    const hw::RoadPrior r = hw::make_road_prior({640, 480}, m, cam, p);
    REQUIRE(r.from_lanes);
    const int y = 350;
    const float lw = m.lane_width_px(float(y));
    CHECK(r.expected_width(y) == doctest::Approx(lw * 1.8 / 3.6).epsilon(1e-5));
    CHECK(r.left(y) == std::max(1, int(std::floor(m.ego_left.x_at(float(y)) - 2 * lw))));
    CHECK(r.right(y) == std::min(638, int(std::ceil(m.ego_right.x_at(float(y)) + 2 * lw))));
}
