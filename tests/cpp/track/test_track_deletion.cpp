// Track deletion: the miss limits of confirmed and tentative tracks, and boxes that left the view of the road.
#include "track/track_deletion.hpp"

#include <doctest/doctest.h>

TEST_CASE("track deletion: a confirmed track survives up to its limit of misses, a tentative one to its own") {
    const hw::MissLimits m{5, 1};
    CHECK_FALSE(hw::missed_out(4, true, m));
    CHECK(hw::missed_out(5, true, m));
    CHECK_FALSE(hw::missed_out(0, false, m));
    CHECK(hw::missed_out(1, false, m));
}

TEST_CASE("track deletion: out of view when too narrow, at the horizon, or beside or below the image") {
    const cv::Size image(640, 480);
    const double horizon = 200.0;
    CHECK_FALSE(hw::out_of_view({100, 250, 40, 30}, horizon, image));
    CHECK(hw::out_of_view({100, 250, 2.9, 2}, horizon, image));        // narrower than 3 px
    CHECK_FALSE(hw::out_of_view({100, 250, 3.0, 2}, horizon, image));
    CHECK(hw::out_of_view({100, 171, 40, 30}, horizon, image));       // bottom 201 <= horizon + 1
    CHECK_FALSE(hw::out_of_view({100, 171.5, 40, 30}, horizon, image));
    CHECK(hw::out_of_view({-41, 250, 40, 30}, horizon, image));       // right side at -1
    CHECK_FALSE(hw::out_of_view({-40, 250, 40, 30}, horizon, image));  // touching column 0
    CHECK(hw::out_of_view({641, 250, 40, 30}, horizon, image));       // left of it past the right side
    CHECK(hw::out_of_view({100, 481, 40, 30}, horizon, image));       // top below the image
}

TEST_CASE("track deletion: erase_flagged keeps the order of the rest") {
    std::vector<int> v{1, 2, 3, 4, 5};
    hw::erase_flagged(v, {true, false, true, false, false});
    CHECK(v == std::vector<int>{2, 4, 5});
}
