// duplicate_pruning.hpp - two tracks on one vehicle (they converged, or one started on a vehicle already tracked):
// one of them goes.
//
// Of each pair that follows the same vehicle, the track measured fewer times goes; on a tie the younger (the
// larger id: ids are handed out in order). Pairs are taken in index order, and a track already going is not
// compared again, so a chain of three overlapping tracks keeps the best of the first pair.
#pragma once

#include <opencv2/core.hpp>

#include <functional>
#include <vector>

namespace hw {

struct TrackRank {
    int id = 0;    // ids grow with the track's start
    int hits = 0;  // measurements so far
};

// Per track, whether it goes; same(i, j) (i < j): tracks i and j follow one vehicle.
std::vector<bool> duplicate_tracks(const std::vector<TrackRank> &tracks,
                                   const std::function<bool(size_t, size_t)> &same);

// The same with the tracks' boxes: tracks whose boxes overlap by IoU >= min_iou follow one vehicle.
std::vector<bool> overlapping_tracks(const std::vector<TrackRank> &tracks, const std::vector<cv::Rect2f> &boxes,
                                     double min_iou);

} // namespace hw
