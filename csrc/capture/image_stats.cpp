#include "capture/image_stats.hpp"

#include <cmath>

namespace hw {

ImageStats ImageStatsMeter::measure(const cv::Mat &gray) {
    constexpr int step = 8;
    cv::Mat samples((gray.rows + step - 1) / step, (gray.cols + step - 1) / step, CV_8UC1);
    for (int r = 0; r < samples.rows; ++r) {
        const uint8_t *src = gray.ptr<uint8_t>(r * step);
        uint8_t *dst = samples.ptr<uint8_t>(r);
        for (int c = 0; c < samples.cols; ++c) dst[c] = src[c * step];
    }
    cv::Scalar mean, stddev;
    cv::meanStdDev(samples, mean, stddev);
    ImageStats s;
    s.mean = float(mean[0]);
    s.stddev = float(stddev[0]);
    s.change = prev_.empty() || prev_.size() != samples.size() ? NAN : float(cv::norm(samples, prev_, cv::NORM_L1) / double(samples.total()));
    prev_ = samples;
    return s;
}

} // namespace hw
