// fuse_detections.hpp - one list of vehicles from the cascade's and the shadow + vertical-edge detector's.
//
// A cascade detection and a verified shadow hypothesis overlapping at IoU >= match_iou are one vehicle:
// the box is the cascade's (trained on whole-vehicle boxes, as the annotations draw them) and the
// confidence min(1, max(c, t) + agree_bonus). A vehicle only the cascade finds keeps its confidence c;
// one only the shadow detector finds keeps thesis_weight * t (the shadow detector alone reaches about
// 0.7 precision on real images, the cascade more). Returned strongest first.
#pragma once

#include "base/params.hpp"
#include "detect/cascade_detector.hpp"
#include "detect/verify.hpp"

#include <vector>

namespace hw {

struct FuseParams {
    double match_iou = 0.5;      // IoU; a cascade and a shadow box overlapping this much are one vehicle
    double agree_bonus = 0.3;    // confidence added when both detectors find the vehicle
    double thesis_weight = 0.5;  // share of its confidence a shadow-only detection keeps

    void bind(ParamMap &m) {
        m.add("match_iou", match_iou, 0.05, 0.95,
              "IoU; a cascade detection and a verified shadow hypothesis overlapping this much are one vehicle");
        m.add("agree_bonus", agree_bonus, 0.0, 1.0, "confidence added when both detectors find the vehicle");
        m.add("thesis_weight", thesis_weight, 0.0, 1.0,
              "share of its confidence kept by a vehicle only the shadow + vertical-edge detector finds");
    }
};

std::vector<Detection> fuse_detections(const std::vector<CascadeDetection> &cascade,
                                       const std::vector<Detection> &shadow, const FuseParams &p);

} // namespace hw
