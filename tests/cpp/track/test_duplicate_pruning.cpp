// Duplicate pruning: of two tracks on one vehicle the one measured fewer times goes, on a tie the younger.
#include "track/duplicate_pruning.hpp"

#include <doctest/doctest.h>

using hw::TrackRank;

TEST_CASE("duplicate pruning: the track with fewer hits goes, whichever came first") {
    const std::vector<cv::Rect2f> boxes{{100, 100, 40, 30}, {102, 101, 40, 30}, {300, 100, 40, 30}};
    const std::vector<bool> a = hw::overlapping_tracks({{1, 3}, {2, 7}, {3, 1}}, boxes, 0.5);
    CHECK(a == std::vector<bool>{true, false, false});
    const std::vector<bool> b = hw::overlapping_tracks({{1, 7}, {2, 3}, {3, 1}}, boxes, 0.5);
    CHECK(b == std::vector<bool>{false, true, false});
}

TEST_CASE("duplicate pruning: on equal hits the younger track (larger id) goes") {
    const std::vector<cv::Rect2f> boxes{{100, 100, 40, 30}, {102, 101, 40, 30}};
    CHECK(hw::overlapping_tracks({{4, 5}, {9, 5}}, boxes, 0.5) == std::vector<bool>{false, true});
    CHECK(hw::overlapping_tracks({{9, 5}, {4, 5}}, boxes, 0.5) == std::vector<bool>{true, false});
}

TEST_CASE("duplicate pruning: boxes overlapping less than the IoU bound are two vehicles") {
    // IoU of these two: 20 x 30 / (1200 + 1200 - 600) = 0.33
    const std::vector<cv::Rect2f> boxes{{100, 100, 40, 30}, {120, 100, 40, 30}};
    CHECK(hw::overlapping_tracks({{1, 1}, {2, 9}}, boxes, 0.5) == std::vector<bool>{false, false});
    CHECK(hw::overlapping_tracks({{1, 1}, {2, 9}}, boxes, 0.3) == std::vector<bool>{true, false});
}

TEST_CASE("duplicate pruning: a track already going is not compared again") {
    // 0 and 1 follow one vehicle, 1 and 2 another pair: 0 (fewer hits) goes first, then 1 against 2, the best of
    // that pair stays; with 0 gone, 0-2 is never compared.
    int compared_0_2 = 0;
    const auto same = [&](size_t i, size_t j) {
        if (i == 0 && j == 2) ++compared_0_2;
        return (i == 0 && j == 1) || (i == 1 && j == 2) || (i == 0 && j == 2);
    };
    const std::vector<bool> g = hw::duplicate_tracks({{1, 2}, {2, 5}, {3, 4}}, same);
    CHECK(g == std::vector<bool>{true, false, true});
    CHECK(compared_0_2 == 0);
}
