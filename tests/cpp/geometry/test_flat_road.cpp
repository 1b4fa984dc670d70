// The flat-road camera model: a road point projected into the image and back lands where it started, the range
// follows Z ~= fy h / (v - v_h) near the axis, and rows above the horizon have no road point.
#include "geometry/flat_road.hpp"

#include <doctest/doctest.h>

TEST_CASE("road point -> pixel -> road point round trip, pitched, yawed and offset") {
    hw::CameraParams cam;
    cam.pitch_deg = 2.0;
    cam.yaw_deg = -1.5;
    cam.lateral_m = 0.3;
    const double vh = cam.horizon_row();
    for (double z : {5.0, 12.0, 40.0, 110.0})
        for (double x : {-5.4, -1.8, 0.0, 2.0}) {
            const cv::Point2d px = hw::project_road_point(cam, x, z, vh);
            const hw::RoadPoint back = hw::road_point(cam, px.x, px.y, vh);
            REQUIRE(back.valid());
            CHECK(back.x_m == doctest::Approx(x).epsilon(1e-9).scale(1));
            CHECK(back.z_m == doctest::Approx(z).epsilon(1e-9));
        }
}

TEST_CASE("range from the row below the horizon, and no road above it") {
    const hw::CameraParams cam;  // 1 deg down, 1.3 m, fy 700
    const double vh = cam.horizon_row();
    CHECK(vh == doctest::Approx(240.0 - 700.0 * std::tan(M_PI / 180.0)));
    const hw::RoadPoint p = hw::road_point(cam, cam.cx, vh + 45.5, vh);
    CHECK(p.z_m == doctest::Approx(700.0 * 1.3 / 45.5).epsilon(2e-3));  // 20 m within 4 cm
    CHECK_FALSE(hw::road_point(cam, cam.cx, vh - 1.0, vh).valid());
    // one row of error at 20 m costs Z^2 / (fy h) metres
    CHECK(hw::range_sigma(cam, 20.0, 1.0) == doctest::Approx(400.0 / 910.0));
}
