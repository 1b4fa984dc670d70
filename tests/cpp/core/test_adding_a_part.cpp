// The walk-through of docs/ARCHITECTURE.md, "Adding a part", kept true: a detector added through the public
// registration alone (no line in the core) is configured, described, offered as a choice and built like the
// shipped ones.
#include "base/part_registry.hpp"
#include "core/config.hpp"
#include "core/parts.hpp"
#include "detect/detector.hpp"

#include <doctest/doctest.h>

#include <string>

namespace {

// Step 1: the part's parameter struct (one commented field per key) and its class.
struct FixedBoxParams {
    double score = 0.5;  // score of the one box it reports

    void bind(hw::ParamMap &m) { m.add("score", score, 0.0, 1.0, "score of the one box it reports"); }
};

// Reports one box in the middle of the road area of every frame.
class FixedBoxDetector final : public hw::Detector {
public:
    explicit FixedBoxDetector(const FixedBoxParams &p) : p_(p) {}
    bool detect(const hw::RoadContext &ctx, std::vector<hw::Hypothesis> &out, hw::StageTimes &) override {
        const float w = ctx.gray.cols / 8.f;
        out.push_back(hw::hypothesis_of({ctx.gray.cols / 2.f - w / 2, ctx.gray.rows / 2.f, w, w}, float(p_.score),
                                        1.f, "fixed_box"));
        return true;
    }

private:
    FixedBoxParams p_;
};

// Step 2: its one registration: name, section and struct, factory.
const bool registered = hw::register_part<hw::Detector, FixedBoxParams>(
    "fixed_box", "fixed_box",
    [](const FixedBoxParams &p, const hw::SectionLookup &) { return std::make_unique<FixedBoxDetector>(p); });

const char *kComposed = R"({"pipeline": {"detectors": ["fixed_box"], "tracker": "kalman"}, "fixed_box": {"score": 0.25}})";

} // namespace

TEST_CASE("a registered detector's section is read, written and described with the core's") {
    hw::Config c = hw::Config::from_json(kComposed);
    CHECK(c.get<FixedBoxParams>("fixed_box").score == doctest::Approx(0.25));
    CHECK(c.to_json()["fixed_box"]["score"].get<double>() == doctest::Approx(0.25));
    const auto described = hw::Config().describe();
    REQUIRE(described.contains("fixed_box"));
    CHECK(described["fixed_box"]["score"]["default"].get<double>() == doctest::Approx(0.5));
    CHECK(described.contains("shadow"));  // the shipped parts' sections stay there
}

TEST_CASE("a registered detector's keys are checked like the core's") {
    CHECK_THROWS_WITH_AS(hw::Config::from_json(R"({"fixed_box": {"score": 2}})"),
                         doctest::Contains("fixed_box.score"), hw::ConfigError);
    CHECK_THROWS_WITH_AS(hw::Config::from_json(R"({"fixed_box": {"scroe": 0.1}})"),
                         doctest::Contains("scroe"), hw::ConfigError);
}

TEST_CASE("a registered detector is a choice of pipeline.detectors and builds into a composition") {
    CHECK((std::string("|") + hw::detector_choices() + "|").find("|fixed_box|") != std::string::npos);
    CHECK(hw::describe_detectors()["fixed_box"]["single_image"].get<bool>());

    const hw::Config c = hw::Config::from_json(kComposed);
    hw::Parts parts = hw::make_parts(c);
    REQUIRE(parts.detectors.parts.size() == 1);
    CHECK(parts.tracker != nullptr);
    CHECK(parts.road == nullptr);  // it compares no two frames

    const cv::Mat gray(480, 640, CV_8UC1, cv::Scalar(90));
    const hw::LaneModel lanes;
    const hw::RoadContext ctx{gray, 0.0, lanes, c.camera, nullptr, true};
    std::vector<hw::Hypothesis> found;
    hw::StageTimes times;
    REQUIRE(parts.detectors.detect(ctx, found, times));
    REQUIRE(found.size() == 1);
    CHECK(found[0].score == doctest::Approx(0.25));
    CHECK(found[0].box.width == doctest::Approx(80));
}

TEST_CASE("a second registration of a taken name is refused") {
    const auto again = [](const char *name, const char *section) {
        return hw::register_part<hw::Detector, FixedBoxParams>(
            name, section, [](const FixedBoxParams &p, const hw::SectionLookup &) {
                return std::make_unique<FixedBoxDetector>(p);
            });
    };
    CHECK_THROWS_AS(again("fixed_box", "fixed_box_again"), std::logic_error);  // the part's name
    CHECK_THROWS_AS(again("fixed_box_again", "shadow"), std::logic_error);     // a section another part owns
    CHECK_FALSE(hw::Config().describe().contains("fixed_box_again"));
}
