#include "track/track_deletion.hpp"

namespace hw {

bool out_of_view(const cv::Rect2d &b, double horizon, cv::Size image) {
    return !(b.width >= 3.0) || b.y + b.height <= horizon + 1.0 || b.x + b.width < 0.0 || b.x > image.width ||
           b.y > image.height;
}

} // namespace hw
