// The detection stage: the learned detections are the primary vehicles, a cue overlapping one (IoU >= match_iou)
// confirms it (score min(1, max(c, t) + agree_bonus), the learned box), a cue nothing learned explains is kept at
// cue_weight of its score; a tracker asking the stage (cues/detection_stage.hpp) gets the same vehicles at once
// as begun on the worker thread and taken later.
#include "detect/fuse_hypotheses.hpp"

#include <doctest/doctest.h>

namespace {

hw::Hypothesis learned(cv::Rect2f box, float score) {
    hw::Hypothesis h = hw::hypothesis_of(box, score, score, "cascade");
    h.appearance = score;
    return h;
}

hw::Hypothesis cue(cv::Rect2f box, float score) { return hw::hypothesis_of(box, score, score, "shadow"); }

// A detector part that finds what it is given.
class FixedDetector final : public hw::Detector {
public:
    explicit FixedDetector(std::vector<hw::Hypothesis> found) : found_(std::move(found)) {}
    bool detect(const hw::RoadContext &, std::vector<hw::Hypothesis> &out, hw::StageTimes &) override {
        out.insert(out.end(), found_.begin(), found_.end());
        return true;
    }

private:
    std::vector<hw::Hypothesis> found_;
};

} // namespace

TEST_CASE("a cue confirms a learned detection and adds the vehicle nothing learned found") {
    const hw::FuseParams p;  // match_iou 0.5, agree_bonus 0.3, cue_weight 0.5
    const cv::Rect2f car(100, 200, 60, 48), shadow_of_car(102, 204, 58, 46), other(400, 220, 40, 32);
    const auto out = hw::fuse_hypotheses({learned(car, 0.6f), cue(shadow_of_car, 0.7f), cue(other, 0.8f)}, p);
    REQUIRE(out.size() == 2);
    CHECK(out[0].box == car);  // the learned box
    CHECK(out[0].score == doctest::Approx(1.0f));  // min(1, max(0.6, 0.7) + 0.3)
    CHECK(out[1].box == other);
    CHECK(out[1].score == doctest::Approx(0.4f));  // 0.5 * 0.8
}

TEST_CASE("a learned detection no cue confirms keeps its score, and shadow_bottom moves a confirmed bottom") {
    hw::FuseParams p;
    const cv::Rect2f car(100, 200, 60, 48), shadow_of_car(100, 206, 60, 48);
    CHECK(hw::fuse_hypotheses({learned(car, 0.55f)}, p)[0].score == doctest::Approx(0.55f));
    p.shadow_bottom = true;
    const auto out = hw::fuse_hypotheses({learned(car, 0.55f), cue(shadow_of_car, 0.5f)}, p);
    REQUIRE(out.size() == 1);
    CHECK(out[0].box.y + out[0].box.height == doctest::Approx(254.f));  // the shadow's bottom row
    CHECK(out[0].foot.y == doctest::Approx(254.f));
    CHECK(out[0].score == doctest::Approx(0.85f));
}

TEST_CASE("a learned box lower than small_box_px takes the box of the shadow cue it holds") {
    hw::FuseParams p;
    p.small_box_px = 24;
    // a car 90 m ahead at 640x480: 14 x 11 px, boxed 22 x 18 by the cascade's smallest window, to the pixel by the
    // shadow's edges; the two overlap at IoU 0.39, below match_iou
    const cv::Rect2f window(335, 222, 22, 18), shadow(339, 227, 14, 11);
    auto out = hw::fuse_hypotheses({learned(window, 0.84f), cue(shadow, 0.4f)}, p);
    REQUIRE(out.size() == 1);
    CHECK(out[0].box == shadow);
    CHECK(out[0].foot.y == doctest::Approx(238.f));
    CHECK(out[0].score == doctest::Approx(1.0f));  // min(1, 0.84 + 0.3)
    // a larger learned box keeps its own, and a cue only partly inside a small one is another vehicle
    p.small_box_px = 18;
    out = hw::fuse_hypotheses({learned(window, 0.84f), cue(shadow, 0.4f)}, p);
    REQUIRE(out.size() == 2);
    CHECK(out[0].box == window);
    p.small_box_px = 24;
    out = hw::fuse_hypotheses({learned(window, 0.84f), cue({350, 227, 14, 11}, 0.4f)}, p);
    REQUIRE(out.size() == 2);
    CHECK(out[0].box == window);
    // a cue that confirms a small box (IoU >= match_iou) but reaches beyond it leaves the learned box as it is
    out = hw::fuse_hypotheses({learned(window, 0.84f), cue({333, 222, 22, 20}, 0.4f)}, p);
    REQUIRE(out.size() == 1);
    CHECK(out[0].box == window);
}

TEST_CASE("the detection stage gives a tracker the same vehicles at once and from the worker thread") {
    hw::DetectorSet set;
    set.parts.push_back(std::make_unique<FixedDetector>(std::vector<hw::Hypothesis>{learned({100, 200, 60, 48}, 0.6f)}));
    set.parts.push_back(std::make_unique<FixedDetector>(
        std::vector<hw::Hypothesis>{cue({102, 204, 58, 46}, 0.7f), cue({400, 220, 40, 32}, 0.8f)}));
    hw::DetectionStage &stage = set;
    const cv::Mat gray(480, 640, CV_8UC1, cv::Scalar(90));
    const hw::LaneModel lanes;
    const hw::CameraParams cam;
    const hw::RoadContext ctx{gray, 0.0, lanes, cam, nullptr};
    std::vector<hw::Hypothesis> now, later;
    hw::StageTimes times;
    REQUIRE(stage.detect(ctx, now, times));
    REQUIRE(stage.can_start());
    stage.start(ctx, 7);
    REQUIRE(stage.finish(later, times));
    REQUIRE(now.size() == 2);
    REQUIRE(later.size() == now.size());
    for (size_t i = 0; i < now.size(); ++i) {
        CHECK(later[i].box == now[i].box);
        CHECK(later[i].score == now[i].score);
    }
    CHECK(set.last_frame == 7);
    set.reset();
}
