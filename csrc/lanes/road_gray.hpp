// road_gray.hpp - the gray level of the ego lane's road, row by row (one image).
//
// What a marking or a dark joint is compared with: the median of the row between the ego boundaries (sampled
// every 2 px, computed once per row asked for). A vehicle ahead in the lane is a minority of the row's pixels.
#pragma once

#include "base/types.hpp"

#include <opencv2/core.hpp>

#include <algorithm>
#include <cmath>
#include <vector>

namespace hw {

class EgoRoadGray {
public:
    EgoRoadGray(const cv::Mat &gray, const LaneBoundary &left, const LaneBoundary &right)
        : gray_(gray), left_(left), right_(right), median_(size_t(gray.rows), -1) {}

    // Median gray of row y between the ego boundaries (their curves); -1 when the row is outside the image or
    // holds no ego-lane pixel.
    int at(int y) {
        if (y < 0 || y >= gray_.rows) return -1;
        int &m = median_[size_t(y)];
        if (m == -1) {
            m = -2;
            const float xl = left_.curve_x(float(y)), xr = right_.curve_x(float(y));
            if (std::isfinite(xl) && std::isfinite(xr)) {
                samples_.clear();
                const uint8_t *row = gray_.ptr<uint8_t>(y);
                for (int i = std::max(0, int(xl)); i <= std::min(gray_.cols - 1, int(xr)); i += 2) samples_.push_back(row[i]);
                if (!samples_.empty()) {
                    std::nth_element(samples_.begin(), samples_.begin() + long(samples_.size() / 2), samples_.end());
                    m = samples_[samples_.size() / 2];
                }
            }
        }
        return m < 0 ? -1 : m;
    }

private:
    const cv::Mat &gray_;
    const LaneBoundary &left_, &right_;
    std::vector<int> median_;  // -1 not computed, -2 none
    std::vector<uint8_t> samples_;
};

} // namespace hw
