// Association: the Hungarian method finds the assignment of least total cost (checked against every
// permutation), never makes a forbidden pair, and the two-stage association pairs confident detections first,
// lets a weak one only keep a track alive at a higher overlap; the greedy pairing (kalman) gives each track in turn
// the unused detection it overlaps most.
#include "track/association.hpp"

#include <doctest/doctest.h>

#include <algorithm>
#include <numeric>
#include <random>

TEST_CASE("hungarian: the least total cost of every assignment, any shape") {
    std::mt19937 rng(11);
    std::uniform_real_distribution<double> u(0.0, 1.0);
    for (int trial = 0; trial < 50; ++trial) {
        const int n = 5;
        cv::Mat_<double> cost(n, n);
        for (auto &c : cost) c = u(rng);
        const std::vector<int> a = hw::hungarian(cost, 1e9);
        double got = 0;
        for (int i = 0; i < n; ++i) got += cost(i, a[size_t(i)]);
        std::vector<int> perm(n);
        std::iota(perm.begin(), perm.end(), 0);
        double best = 1e18;
        do {
            double s = 0;
            for (int i = 0; i < n; ++i) s += cost(i, perm[size_t(i)]);
            best = std::min(best, s);
        } while (std::next_permutation(perm.begin(), perm.end()));
        CHECK(got == doctest::Approx(best).epsilon(1e-12));
    }
    // more rows than columns: one row unpaired; a forbidden pair is never made
    cv::Mat_<double> tall = (cv::Mat_<double>(3, 2) << 0.1, 5.0, 5.0, 0.2, 0.3, 5.0);
    const std::vector<int> t = hw::hungarian(tall, 5.0);
    CHECK(t == std::vector<int>{0, 1, -1});
}

TEST_CASE("two-stage association: confident first, a weak detection only keeps a track at low_match_iou") {
    hw::AssociationParams p;  // match_iou 0.3, high_score 0.5, low_match_iou 0.5
    // tracks x detections
    cv::Mat_<float> iou = (cv::Mat_<float>(3, 3) << 0.6, 0.0, 0.55,  //
                           0.35, 0.0, 0.0,                          //
                           0.0, 0.45, 0.0);
    const std::vector<float> scores{0.9, 0.3, 0.2};
    const std::vector<int> a = hw::associate(iou, scores, p);
    // track 0 takes the confident detection 0 (0.6); track 1 gets nothing (its only pair, 0.35, went to track 0);
    // track 2's weak detection 1 overlaps 0.45 < 0.5: not paired
    CHECK(a == std::vector<int>{0, -1, -1});
    // the total overlap decides, not the order: track 1 takes detection 0 when track 0 has a better one
    cv::Mat_<float> iou2 = (cv::Mat_<float>(2, 2) << 0.6, 0.58, 0.5, 0.0);
    CHECK(hw::associate(iou2, {0.9f, 0.9f}, p) == std::vector<int>{1, 0});
    // a weak detection at 0.55 keeps track 0 alive when no confident one is there
    cv::Mat_<float> iou3 = (cv::Mat_<float>(1, 1) << 0.55);
    CHECK(hw::associate(iou3, {0.2f}, p) == std::vector<int>{0});
}

TEST_CASE("association: a detection under low_score pairs with no track") {
    hw::AssociationParams p;  // low_score 0.1, as ByteTrack's low threshold
    // a 0.01-scored box over a vehicle (the verifier: no vehicle) keeps nothing alive, at any overlap
    cv::Mat_<float> iou = (cv::Mat_<float>(1, 2) << 0.9, 0.6);
    CHECK(hw::associate(iou, {0.01f, 0.2f}, p) == std::vector<int>{1});
    CHECK(hw::associate(iou, {0.01f, 0.05f}, p) == std::vector<int>{-1});
    p.low_score = 0.0;  // every detection may pair
    CHECK(hw::associate(iou, {0.01f, 0.05f}, p) == std::vector<int>{0});
}

TEST_CASE("take_best_unused: in the tracks' order, each takes the unused detection it overlaps most") {
    std::vector<bool> used(3, false);
    // the first track overlaps detection 1 most and takes it, though the second overlaps it more
    CHECK(hw::take_best_unused({0.35f, 0.6f, 0.f}, used, 0.3f) == 1);
    CHECK(used == std::vector<bool>{false, true, false});
    CHECK(hw::take_best_unused({0.f, 0.9f, 0.4f}, used, 0.3f) == 2);
    // nothing left at the overlap asked for: none, and nothing marked
    CHECK(hw::take_best_unused({0.29f, 0.9f, 0.9f}, used, 0.3f) == -1);
    CHECK(used == std::vector<bool>{false, true, true});
    // the bound itself pairs; of equal overlaps the later detection
    std::vector<bool> fresh(3, false);
    CHECK(hw::take_best_unused({0.3f, 0.f, 0.f}, fresh, 0.3f) == 0);
    CHECK(hw::take_best_unused({0.f, 0.5f, 0.5f}, fresh, 0.3f) == 2);
}
