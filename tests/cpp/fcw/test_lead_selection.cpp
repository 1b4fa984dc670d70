// Lead selection: with a believed lane model the nearest vehicle in the ego lane is the lead and each vehicle
// gets its lane; without lanes the ego path from the yaw rate decides, bending with the curve; a box not
// standing on the road is never the lead; a lead drifting out keeps its place until it has left the lane.
#include "fcw/lead_selection.hpp"
#include "../road_scene.hpp"

#include <doctest/doctest.h>

namespace {

const hw::CameraParams kCam;  // 700 px focal length, 1.3 m high, 1 deg down

// A 1.8 m wide, 1.5 m high car whose rear centre stands at (x, z) on the road.
hw::TrackState car(int id, double x, double z) {
    const double vh = kCam.horizon_row();
    const cv::Point2d foot = hw::project_road_point(kCam, x, z, vh);
    const double w = kCam.fx * 1.8 / z, h = kCam.fy * 1.5 / z;
    hw::TrackState t;
    t.id = id;
    t.confirmed = true;
    t.box = cv::Rect2f(float(foot.x - w / 2), float(foot.y - h), float(w), float(h));
    t.range_m = float(z);
    t.lateral_m = float(x);
    return t;
}

} // namespace

TEST_CASE("with lanes: the nearest car in the ego lane is the lead, each car gets its lane") {
    hw::LeadSelector sel({}, kCam);
    std::vector<hw::TrackState> tracks{car(1, 3.6, 15.0), car(2, 0.0, 30.0), car(3, -3.6, 12.0), car(4, 0.2, 60.0)};
    const int lead = sel.update(tracks, hw_test::ego_lane(kCam), {}, kCam.horizon_row());
    CHECK(lead == 2);
    CHECK(tracks[0].lane_index == 1);
    CHECK(tracks[1].lane_index == 0);
    CHECK(tracks[2].lane_index == -1);
    CHECK(tracks[0].in_path == 0);
    CHECK(tracks[1].in_path == 1);
    CHECK(tracks[3].in_path == 1);
}

TEST_CASE("without lanes: the path bends with the yaw rate") {
    hw::LeadSelector sel({}, kCam);
    // 0.1 rad/s at 20 m/s: curvature 0.005 1/m, the path 4 m to the left at 40 m
    std::vector<hw::TrackState> tracks{car(1, -4.0, 40.0), car(2, 0.0, 45.0)};
    CHECK(sel.update(tracks, {}, {20.0, 0.1}, kCam.horizon_row()) == 1);
    CHECK(tracks[1].in_path == 0);
    sel.reset();
    CHECK(sel.update(tracks, {}, {20.0, 0.0}, kCam.horizon_row()) == 2);  // straight on
    CHECK(tracks[0].in_path == 0);
}

TEST_CASE("a box whose bottom is above the horizon is never the lead") {
    hw::LeadSelector sel({}, kCam);
    hw::TrackState sign = car(7, 0.0, 30.0);
    sign.box.y = float(kCam.horizon_row() - sign.box.height - 5.0);
    std::vector<hw::TrackState> tracks{sign};
    CHECK(sel.update(tracks, hw_test::ego_lane(kCam), {}, kCam.horizon_row()) == -1);
    CHECK(tracks[0].in_path == 0);
}

TEST_CASE("the lead keeps its place while drifting within the lane, a newcomer needs a clear overlap") {
    hw::LeadSelector sel({}, kCam);
    // 1.8 m wide cars against a lane from -1.8 to 1.8: at x = 2.3 m 0.4 m of 1.8 (22 %) is inside the lane
    std::vector<hw::TrackState> tracks{car(1, 0.0, 25.0)};
    REQUIRE(sel.update(tracks, hw_test::ego_lane(kCam), {}, kCam.horizon_row()) == 1);
    tracks = {car(1, 2.3, 25.0)};
    CHECK(sel.update(tracks, hw_test::ego_lane(kCam), {}, kCam.horizon_row()) == 1);  // above exit_overlap 0.05
    hw::LeadSelector fresh({}, kCam);
    tracks = {car(1, 2.3, 25.0)};
    CHECK(fresh.update(tracks, hw_test::ego_lane(kCam), {}, kCam.horizon_row()) == -1);  // under enter_overlap 0.35
    tracks = {car(1, 2.8, 25.0)};  // 0.1 m inside: left the lane
    CHECK(sel.update(tracks, hw_test::ego_lane(kCam), {}, kCam.horizon_row()) == -1);
}
