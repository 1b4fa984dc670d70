// track_deletion.hpp - when a track has ended: missed too often, or its box has left the view of the road.
//
// A confirmed track may be missed `confirmed` times in a row, a tentative one `tentative` times (a tentative track
// is more likely a false detection). A box has left the view when it is narrower than 3 px, when its bottom is at
// or above the horizon (+1 px: nothing on the road stands there), or when it lies wholly beside or below the image.
#pragma once

#include <opencv2/core.hpp>

#include <vector>

namespace hw {

struct MissLimits {
    int confirmed = 5;  // misses in a row that end a confirmed track
    int tentative = 1;  // ... a tentative one
};

// Whether `misses` misses in a row end a track.
inline bool missed_out(int misses, bool confirmed, const MissLimits &m) {
    return misses >= (confirmed ? m.confirmed : m.tentative);
}

// Whether the box has left the view of the road (see above). horizon: this frame's horizon row.
bool out_of_view(const cv::Rect2d &box, double horizon, cv::Size image);

// Removes the elements whose flag is set, keeping the order of the rest.
template <class T> void erase_flagged(std::vector<T> &items, const std::vector<bool> &flagged) {
    size_t o = 0;
    for (size_t i = 0; i < items.size(); ++i)
        if (!flagged[i]) {
            if (o != i) items[o] = std::move(items[i]);
            ++o;
        }
    items.erase(items.begin() + long(o), items.end());
}

} // namespace hw
