// Lane curve fitting: marking points on the image of a road curving with a 1000 m radius bend the tracked
// straight boundaries to x = a + b d + c / d with c = fx fy h C / 2 of that curvature, and the bent boundaries
// pass through the markings far beyond the rows the straight lines were tracked on.
#include "lanes/lane_curve.hpp"
#include "lanes/marking_filter.hpp"

#include <doctest/doctest.h>

#include <random>

namespace {

const hw::CameraParams kCam;  // fx = fy = 700, 1.3 m high, 1 deg down

struct Road {
    double a, c;  // px, px^2
    double x(double lateral_m, double d) const { return a + kCam.fx * lateral_m / (kCam.fy * kCam.height_m) * d + c / d; }
};

// Marking points of the boundaries at +-1.8 m, one per row from the row of 90 m to the bottom, 0.3 px noise.
std::vector<hw::MarkingPoint> markings(const Road &road, double y_h, uint32_t seed) {
    std::mt19937 rng(seed);
    std::normal_distribution<float> noise(0.f, 0.3f);
    std::vector<hw::MarkingPoint> pts;
    for (int y = int(std::ceil(y_h + kCam.fy * kCam.height_m / 90.0)); y < 475; ++y)
        for (double lat : {-1.8, 1.8}) pts.push_back({float(road.x(lat, y - y_h)) + noise(rng), float(y), 50.f, 4.f});
    return pts;
}

// The boundaries as the lane tracker hands them over: straight chords of the markings from the bottom row to
// the row of 25 m.
hw::LaneModel straight_lanes(const Road &road, double y_h) {
    hw::LaneModel m;
    const double d_bottom = 470 - y_h, d_top = kCam.fy * kCam.height_m / 25.0;
    for (auto [b, lat] : {std::pair<hw::LaneBoundary *, double>{&m.ego_left, -1.8}, {&m.ego_right, 1.8}}) {
        b->valid = b->observed = true;
        b->bottom = {float(road.x(lat, d_bottom)), float(y_h + d_bottom)};
        b->top = {float(road.x(lat, d_top)), float(y_h + d_top)};
    }
    m.valid = true;
    return m;
}

} // namespace

TEST_CASE("lane curves: the curvature term of a 1000 m bend, and the boundaries on the far markings") {
    const double y_h = kCam.horizon_row();
    const Road road{kCam.cx, kCam.fx * kCam.fy * kCam.height_m / (2 * 1000.0)};  // c = 318.5 px^2
    hw::LaneCurveParams p;
    hw::LaneCurveState state;
    hw::LaneModel m;
    for (uint32_t frame = 0; frame < 5; ++frame) {  // the curvature carried over frames as the tracker does
        m = straight_lanes(road, y_h);
        hw::fit_lane_curves(markings(road, y_h, frame), float(y_h), kCam, 3.6f, p, state, m);
    }
    REQUIRE(state.known);
    CHECK(std::abs(state.c - road.c) < 0.05 * road.c);
    CHECK(m.ego_left.curve == doctest::Approx(state.c));
    // at 80 m (d = 11.4 px, where c / d bends the markings by 28 px) the boundaries are within 1 px of them
    const double d80 = kCam.fy * kCam.height_m / 80.0;
    CHECK(std::abs(m.ego_left.curve_x(float(y_h + d80)) - road.x(-1.8, d80)) < 1.0);
    CHECK(std::abs(m.ego_right.curve_x(float(y_h + d80)) - road.x(1.8, d80)) < 1.0);
    // the straight chord misses them there by far more
    hw::LaneModel chord = straight_lanes(road, y_h);
    CHECK(std::abs(chord.ego_left.x_at(float(y_h + d80)) - road.x(-1.8, d80)) > 10.0);
}

TEST_CASE("lane curves: a straight road stays straight, and curve_enabled false leaves the lines") {
    const double y_h = kCam.horizon_row();
    const Road road{kCam.cx, 0.0};
    hw::LaneCurveParams p;
    hw::LaneCurveState state;
    hw::LaneModel m = straight_lanes(road, y_h);
    hw::fit_lane_curves(markings(road, y_h, 9), float(y_h), kCam, 3.6f, p, state, m);
    CHECK(std::abs(state.c) < 10.0);  // under 0.3 px of bend at 80 m
    p.enabled = false;
    hw::LaneModel off = straight_lanes(Road{kCam.cx, 318.5}, y_h);
    const hw::LaneModel before = off;
    hw::LaneCurveState s2;
    hw::fit_lane_curves(markings(Road{kCam.cx, 318.5}, y_h, 9), float(y_h), kCam, 3.6f, p, s2, off);
    CHECK(off.ego_left.curve == 0.f);
    CHECK(off.ego_left.top.x == before.ego_left.top.x);
}
