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
