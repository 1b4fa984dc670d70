// The tracker's frame clock: time steps between frames, and gaps that void the predictions.
#include "track/frame_clock.hpp"

#include <doctest/doctest.h>

TEST_CASE("frame clock: steps between frames, 0 on the first") {
    hw::FrameClock c(1.0);
    bool gap = true;
    CHECK(c.step(10.0, gap) == 0.0);
    CHECK_FALSE(gap);
    CHECK(c.step(10.25, gap) == 0.25);
    CHECK_FALSE(gap);
    CHECK(c.step(11.25, gap) == 1.0);  // exactly max_dt_s: still one run
    CHECK_FALSE(gap);
}

TEST_CASE("frame clock: a longer step or time going back is a gap with step 0") {
    hw::FrameClock c(1.0);
    bool gap = false;
    c.step(5.0, gap);
    CHECK(c.step(6.5, gap) == 0.0);
    CHECK(gap);
    CHECK(c.step(6.75, gap) == 0.25);  // counted from the gap's frame
    CHECK_FALSE(gap);
    CHECK(c.step(6.0, gap) == 0.0);
    CHECK(gap);
}

TEST_CASE("frame clock: after reset the next frame is a first frame") {
    hw::FrameClock c(1.0);
    bool gap = false;
    c.step(5.0, gap);
    c.reset();
    CHECK(c.step(100.0, gap) == 0.0);
    CHECK_FALSE(gap);
}
