// association.hpp - which detection is which tracked vehicle: optimal assignment on box overlap, in two stages
// by detection score (ByteTrack, Zhang et al. 2022).
//
// The tracker gives the IoU of every (track, detection) pair, each track's box predicted to this frame by its
// motion model. Stage 1 assigns the confident detections (score >= high_score) to the tracks by the Hungarian
// method, the total IoU the largest, pairs under match_iou not allowed. Stage 2 assigns the weak detections (score <
// high_score, and at least low_score) to the tracks stage 1 left, at IoU >= low_match_iou: a weak detection keeps a
// vehicle alive (a partly hidden or blurred one scores low) but never starts one, so the tracker starts vehicles only
// from the confident detections no track took.
#pragma once

#include "base/params.hpp"

#include <opencv2/core.hpp>

#include <vector>

namespace hw {

struct AssociationParams {
    double match_iou = 0.3;      // IoU; a confident detection and a track overlapping less are not paired
    double high_score = 0.5;     // score; detections from here are matched first and may start a vehicle
    double low_match_iou = 0.5;  // IoU; a weak detection pairs with a track left over only from here
    double low_score = 0.1;      // score; a detection under this pairs with nothing (ByteTrack's low threshold)

    void bind(ParamMap &m) {
        m.add("match_iou", match_iou, 0.0, 1.0,
              "IoU of a confident detection with a vehicle's predicted box from which they may be paired (the pairs "
              "are chosen together, the total overlap the largest: Hungarian method)");
        m.add("high_score", high_score, 0.0, 1.0,
              "detection score from which a detection is confident: paired first, and may start a vehicle; a weaker "
              "one only keeps a vehicle the confident ones left alive (two-stage association, as ByteTrack)");
        m.add("low_match_iou", low_match_iou, 0.0, 1.0,
              "IoU of a weak detection with a vehicle's predicted box from which they may be paired");
        m.add("low_score", low_score, 0.0, 1.0,
              "detection score under which a detection pairs with no vehicle (ByteTrack's low threshold, 0.1): the "
              "verifier's near-certain non-vehicles keep nothing alive");
    }
};

// The assignment minimising the total cost, a row or column left unpaired costing 0; cost(i, j) >= `forbidden`
// marks a pair that is never made. Returns, per row, its column or -1. Any shape.
std::vector<int> hungarian(const cv::Mat_<double> &cost, double forbidden);

// The detection paired with each track (index into scores, or -1), in two stages by score (see above).
// iou: tracks x detections.
std::vector<int> associate(const cv::Mat_<float> &iou, const std::vector<float> &scores, const AssociationParams &p);

// Greedy pairing, one track at a time in the tracker's order (kalman, whose tracks the ROI search did not find):
// of the detections not yet used, the one the track overlaps most at IoU >= min_iou (of equal overlaps the later),
// marked used; -1 when none. iou: the track's overlap with every detection. Unlike associate(), an earlier track
// may take the detection a later one overlaps more, and the scores play no part.
int take_best_unused(const std::vector<float> &iou, std::vector<bool> &used, float min_iou);

} // namespace hw
