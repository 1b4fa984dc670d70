// The birth gate: a detection on a tracked vehicle starts no second vehicle; one beside it does.
#include "track/birth_gate.hpp"

#include <doctest/doctest.h>

using hw::BirthGateParams;
using hw::on_tracked_vehicle;

TEST_CASE("birth gate: a detection overlapping a tracked box by IoU 0.2 or more is that vehicle") {
    const std::vector<cv::Rect2f> tracked{{100, 100, 50, 40}};
    // shifted 30 px right: overlap 20 x 40 = 800, union 3200, IoU 0.25; its foot (155, 140) is outside the box
    CHECK(on_tracked_vehicle({130, 100, 50, 40}, tracked, BirthGateParams{}));
    // shifted 40 px right: IoU 10 x 40 / 3600 = 0.11, foot (165, 140) outside: a new vehicle
    CHECK_FALSE(on_tracked_vehicle({140, 100, 50, 40}, tracked, BirthGateParams{}));
}

TEST_CASE("birth gate: a small detection whose foot stands inside a tracked box is part of it") {
    const std::vector<cv::Rect2f> tracked{{100, 100, 50, 40}};
    // a 10 x 6 px window on the vehicle: IoU 0.03, foot (125, 116) inside
    CHECK(on_tracked_vehicle({120, 110, 10, 6}, tracked, BirthGateParams{}));
    // the box's edges count as inside: foot exactly on the bottom row and the right side
    CHECK(on_tracked_vehicle({145, 134, 10, 6}, tracked, BirthGateParams{}));
    // the same window 1 px below the bottom row: outside
    CHECK_FALSE(on_tracked_vehicle({145, 135, 10, 6}, tracked, BirthGateParams{}));
}

TEST_CASE("birth gate: no tracked vehicle explains nothing") {
    CHECK_FALSE(on_tracked_vehicle({0, 0, 10, 10}, {}, BirthGateParams{}));
}

TEST_CASE("birth gate: the beside rule, when on, takes a detection on the vehicle's bottom row over its columns") {
    const std::vector<cv::Rect2f> tracked{{100, 100, 40, 30}};  // bottom row 130
    // a 40 px box to its right, bottom 2 px lower, overlapping 12 px of columns (0.3 of the narrower width); IoU
    // 12 x 28 / (1200 + 1200 - 336) = 0.16, foot (148, 132) outside
    const cv::Rect2f beside{128, 102, 40, 30};
    CHECK_FALSE(on_tracked_vehicle(beside, tracked, BirthGateParams{}));  // off by default
    BirthGateParams p;
    p.beside_overlap = 0.25;
    p.beside_bottom_tol = 0.2;  // 8 px of the 40 px width
    CHECK(on_tracked_vehicle(beside, tracked, p));
    p.beside_overlap = 0.35;  // 12 px of 40 are too few
    CHECK_FALSE(on_tracked_vehicle(beside, tracked, p));
    p.beside_overlap = 0.25;
    // 10 px lower: bottoms 12 px apart, more than 8: another range
    CHECK_FALSE(on_tracked_vehicle({128, 112, 40, 30}, tracked, p));
}
