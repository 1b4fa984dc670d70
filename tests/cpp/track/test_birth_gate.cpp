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

TEST_CASE("birth gate: the nearer rule, when on, lets a vehicle in front of a tracked one start") {
    // a track started from a box the image's side cut short: 57 x 68 px, bottom row 277
    const std::vector<cv::Rect2f> tracked{{548, 209, 57, 68}};
    // the whole car, found later: across the track's columns, bottom row 335 (58 px lower, 0.85 of its height);
    // IoU 0.25 with the short box, so by overlap it is part of the tracked vehicle
    const cv::Rect2f whole{545, 175, 95, 160};
    CHECK(on_tracked_vehicle(whole, tracked, BirthGateParams{}));  // off by default
    BirthGateParams p;
    p.nearer_below = 0.5;
    CHECK_FALSE(on_tracked_vehicle(whole, tracked, p));
    p.nearer_below = 0.9;  // 58 px is under 0.9 of 68: not far enough below
    CHECK(on_tracked_vehicle(whole, tracked, p));
    p.nearer_below = 0.5;
    // as low, but not across the tracked box's columns (its left side 10 px right of the track's): part of it
    CHECK(on_tracked_vehicle({558, 175, 82, 160}, tracked, p));
}
