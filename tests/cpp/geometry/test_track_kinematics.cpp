// The TTCs of a track whose tracker estimates range and range rate itself (the phd tracker's UKF): the rate is
// reported once its sigma is below 2 m/s, and before that it still judges the scale TTC of the box's growth.
#include "geometry/track_kinematics.hpp"

#include <doctest/doctest.h>

#include <cmath>

namespace {

// A car `range_m` ahead whose box widens from `w0` to `w1` px over 12 frames at 30 fps, the tracker giving
// `rate` +- `sigma` m/s; returns the last frame's track.
hw::TrackState grow(double range_m, float w0, float w1, float rate, float sigma,
                    const hw::KinematicsParams &p = hw::KinematicsParams{}) {
    hw::TrackKinematics kin(p, hw::CameraParams{});
    hw::TrackState out;
    for (int k = 0; k < p.scale_window; ++k) {
        hw::TrackState tr;
        tr.id = 4;
        tr.confirmed = true;
        const float w = w0 + (w1 - w0) * float(k) / float(p.scale_window - 1);
        tr.box = cv::Rect2f(320.f - 0.5f * w, 200.f, w, 0.8f * w);
        tr.range_m = float(range_m);
        tr.range_rate_mps = rate;
        tr.range_rate_sigma_mps = sigma;
        std::vector<hw::TrackState> tracks{tr};
        kin.update(tracks, 230.0, k / 30.0);
        out = tracks[0];
    }
    return out;
}

} // namespace

TEST_CASE("an unsettled rate is not reported, a settled one is, with its range TTC") {
    const hw::TrackState unsettled = grow(40.0, 30.f, 30.f, -5.f, 2.5f);
    CHECK(std::isnan(unsettled.range_rate_mps));
    CHECK(std::isnan(unsettled.ttc_s));
    const hw::TrackState settled = grow(40.0, 30.f, 30.f, -5.f, 1.5f);
    CHECK(settled.range_rate_mps == doctest::Approx(-5.0));
    CHECK(settled.ttc_s == doctest::Approx((40.0 - 2.0) / 5.0));
}

TEST_CASE("a far box's growth that the unsettled rate denies gives no scale TTC") {
    // solidWhiteRight's lead 77 m ahead (fuse.small_box_px 24), its box 18 -> 21 px in 12 frames (32 m/s of
    // closing, TTC 2.3 s), while the UKF says -4.6 +- 2.4 m/s
    CHECK(std::isnan(grow(77.0, 18.f, 21.f, -4.6f, 2.4f).ttc_scale_s));
    // the same growth with no rate from the tracker: the scale TTC stands in
    const hw::TrackState alone = grow(77.0, 18.f, 21.f, NAN, NAN);
    REQUIRE(std::isfinite(alone.ttc_scale_s));
    const double m = hw::KinematicsParams{}.scale_margin_px;  // the box's margin, off the width before the fit
    const double scale_rate = std::log((21.0 - m) / (18.0 - m)) / (11.0 / 30.0);  // d(ln w)/dt of the vehicle
    CHECK(alone.ttc_scale_s == doctest::Approx((77.0 - 2.0) / 77.0 / scale_rate).epsilon(0.01));
}

TEST_CASE("a stopped car closing at 28 m/s keeps its scale TTC while the UKF's rate still lags") {
    // stopped_lead_100kmh at 2.8 s: 72 m ahead, the vehicle 19.4 -> 22.4 px wide in 0.37 s (28.5 m/s of closing),
    // the UKF at -7.1 +- 6.1 m/s
    hw::KinematicsParams vehicle_width;  // the widths are the vehicle's own: no margin to take off
    vehicle_width.scale_margin_px = 0.0;
    const hw::TrackState tr = grow(72.6, 19.4f, 22.4f, -7.1f, 6.1f, vehicle_width);
    REQUIRE(std::isfinite(tr.ttc_scale_s));
    CHECK(tr.ttc_scale_s < 3.0f);
}

TEST_CASE("the box's margin beyond the vehicle is taken off before the scale fit") {
    // A car 2.0 m wide, 70 m ahead, closing at 27.8 m/s (a stopped car at 100 km/h) seen with fx 1000: 28.6 px
    // wide, and 12 frames later (0.37 s) 59.8 m ahead and 33.4 px wide; the detector boxes it 3 px wider
    // (docs/tracking.md).
    const double fx = 1000.0, w_m = 2.0, z0 = 70.0, v = 27.8, z1 = z0 - v * 11.0 / 30.0;
    const float w0 = float(fx * w_m / z0), w1 = float(fx * w_m / z1);
    hw::KinematicsParams with_margin, no_margin;
    with_margin.scale_margin_px = 3.0;
    no_margin.scale_margin_px = 0.0;
    const hw::TrackState vehicle = grow(z1, w0, w1, NAN, NAN, no_margin);  // the vehicle's own width
    REQUIRE(std::isfinite(vehicle.ttc_scale_s));
    CHECK(vehicle.ttc_scale_s == doctest::Approx((z1 - 2.0) / v).epsilon(0.1));  // the window's lag: < 10 %
    const hw::TrackState corrected = grow(z1, w0 + 3.f, w1 + 3.f, NAN, NAN, with_margin);
    CHECK(corrected.ttc_scale_s == doctest::Approx(vehicle.ttc_scale_s).epsilon(0.01));
    const hw::TrackState raw = grow(z1, w0 + 3.f, w1 + 3.f, NAN, NAN, no_margin);
    REQUIRE(std::isfinite(raw.ttc_scale_s));
    CHECK(raw.ttc_scale_s > 1.08 * vehicle.ttc_scale_s);  // too long by about margin / width: a later warning
}

TEST_CASE("a tracked box is reported without the detector's margin, the TTCs and a single image's box as before") {
    hw::KinematicsParams margin;
    margin.box_margin_px = 1.5;
    margin.box_margin_frac = 0.06;
    // a car 20 px high, 26 px wide, 77 m ahead: 1.5 + 0.06 x 20 = 2.7 px off, 1.35 px each side
    const hw::TrackState plain = grow(77.0, 24.f, 26.f, NAN, NAN);
    const hw::TrackState cut = grow(77.0, 24.f, 26.f, NAN, NAN, margin);
    const float h = plain.box.height;
    CHECK(cut.box.width == doctest::Approx(plain.box.width - (1.5 + 0.06 * h)));
    CHECK(cut.box.x + 0.5f * cut.box.width == doctest::Approx(plain.box.x + 0.5f * plain.box.width));  // centre kept
    CHECK(cut.box.y == plain.box.y);
    CHECK(cut.box.height == plain.box.height);  // the bottom row, which the range reads, kept
    REQUIRE(std::isfinite(plain.ttc_scale_s));
    CHECK(cut.ttc_scale_s == plain.ttc_scale_s);  // the scale fit reads the box as detected
    // a single image's detection (id -1) is reported as the detector found it
    hw::TrackKinematics kin(margin, hw::CameraParams{});
    hw::TrackState det;
    det.id = -1;
    det.box = cv::Rect2f(300.f, 250.f, 40.f, 30.f);
    std::vector<hw::TrackState> dets{det};
    kin.update(dets, 230.0, 0.0);
    CHECK(dets[0].box == det.box);
}
