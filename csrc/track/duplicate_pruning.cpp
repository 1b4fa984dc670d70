#include "track/duplicate_pruning.hpp"

#include "base/types.hpp"

namespace hw {

std::vector<bool> duplicate_tracks(const std::vector<TrackRank> &tracks,
                                   const std::function<bool(size_t, size_t)> &same) {
    std::vector<bool> goes(tracks.size(), false);
    for (size_t i = 0; i < tracks.size(); ++i)
        for (size_t j = i + 1; j < tracks.size(); ++j) {
            if (goes[i] || goes[j] || !same(i, j)) continue;
            const TrackRank &a = tracks[i], &b = tracks[j];
            goes[a.hits > b.hits || (a.hits == b.hits && a.id < b.id) ? j : i] = true;
        }
    return goes;
}

std::vector<bool> overlapping_tracks(const std::vector<TrackRank> &tracks, const std::vector<cv::Rect2f> &boxes,
                                     double min_iou) {
    CV_Assert(boxes.size() == tracks.size());
    return duplicate_tracks(tracks, [&](size_t i, size_t j) { return box_iou(boxes[i], boxes[j]) >= min_iou; });
}

} // namespace hw
