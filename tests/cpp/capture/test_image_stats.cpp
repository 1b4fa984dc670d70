// ImageStatsMeter: the mean, spread and change of a frame on the sparse grid are the closed-form values for
// images whose samples are known: a blinded (constant) frame has no spread, a frozen one no change.
#include "capture/image_stats.hpp"

#include <doctest/doctest.h>
#include <opencv2/core.hpp>

#include <cmath>

TEST_CASE("a constant frame: its gray level, no spread; the first frame has no change, a repeat changes 0") {
    hw::ImageStatsMeter m;
    const cv::Mat grey(480, 640, CV_8U, cv::Scalar(117));
    const hw::ImageStats first = m.measure(grey);
    CHECK(first.mean == doctest::Approx(117.0));
    CHECK(first.stddev == doctest::Approx(0.0));
    CHECK(std::isnan(first.change));
    CHECK(m.measure(grey).change == doctest::Approx(0.0));  // frozen
}

TEST_CASE("two gray levels in equal shares: mean between them, spread half their difference, change measured") {
    hw::ImageStatsMeter m;
    cv::Mat img(480, 640, CV_8U, cv::Scalar(40));
    img.colRange(320, 640).setTo(200);  // the grid's columns split evenly between the halves
    const hw::ImageStats s = m.measure(img);
    CHECK(s.mean == doctest::Approx(120.0).epsilon(0.01));
    CHECK(s.stddev == doctest::Approx(80.0).epsilon(0.01));
    cv::Mat brighter = img + cv::Scalar(10);
    CHECK(m.measure(brighter).change == doctest::Approx(10.0).epsilon(1e-4));
    m.reset();
    CHECK(std::isnan(m.measure(brighter).change));  // after reset: a first frame again
}
