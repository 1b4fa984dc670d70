// image_stats.hpp - cheap per-frame image health: brightness, contrast and change since the last frame.
//
// The supervisor calls the camera degraded when the picture is blinded (near-constant: sun glare,
// a covered lens, a dead sensor) or frozen (identical frames: a hung driver repeating its buffer).
// Both show in three numbers computed on a sparse grid (every 8th pixel of every 8th row: ~4800
// samples at 640x480, a few microseconds), so this costs nothing per frame.
#pragma once

#include <opencv2/core.hpp>

namespace hw {

struct ImageStats {
    float mean = 0.f;    // gray level
    float stddev = 0.f;  // gray levels; near 0 = blinded
    float change = 0.f;  // mean |difference| to the previous frame's samples; 0 = frozen (first frame: NaN)
};

class ImageStatsMeter {
public:
    ImageStats measure(const cv::Mat &gray);
    void reset() { prev_.release(); }

private:
    cv::Mat prev_;  // last frame's samples
};

} // namespace hw
