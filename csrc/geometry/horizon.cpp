#include "geometry/horizon.hpp"

#include <algorithm>
#include <cmath>

namespace hw {

double HorizonTracker::update(const LaneModel &lanes) {
    const double calibrated = cam_.horizon_row();
    const bool measured = p_.use_lanes && lanes.certain && lanes.ego_left.observed && lanes.ego_right.observed &&
                          std::isfinite(lanes.vanishing_point.y);
    if (measured) {
        const double target =
            std::clamp(double(lanes.vanishing_point.y), calibrated - p_.max_offset_px, calibrated + p_.max_offset_px);
        row_ += p_.alpha * (target - row_);  // first-order low-pass: row += alpha (measured - row)
    } else {
        row_ += p_.return_alpha * (calibrated - row_);
    }
    return row_;
}

} // namespace hw
