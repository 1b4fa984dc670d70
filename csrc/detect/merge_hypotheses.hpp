// merge_hypotheses.hpp - one list of vehicles from several detectors' hypotheses, verified once (issue 12).
//
// The detectors of a composition (cascade, shadow, parallax, ...) each give unverified hypotheses
// (Detector::unverified). They are merged first: two hypotheses are the same vehicle when their
// bottom rows lie within bottom_tol of their width of each other and their column spans overlap by
// at least span_iou (1-D IoU). A merged vehicle takes its bottom edge and sides from its anchor, the
// member with the most precise bottom: a measured shadow edge (road_gray known), else a learned
// appearance (the cascade's box), else any (a parallax region). A vehicle without a shadow edge that
// one detector alone found needs a cascade score of at least min_appearance, and to stand on the ego lane
// or within appearance_lanes lane widths of it (with a lane model: x_l(y) - k w(y) <= u <= x_r(y) + k w(y)
// at its bottom row y, w the ego lane's width there).
// Then ONE verification, the shadow detector's (verify.hpp, verify_one): the vehicle width expected
// at the bottom row (road_prior.hpp, from the lane model or the flat-road camera), two vertical-edge
// sides standing out against the road, the road's texture under the bottom edge (standing on the
// road), the top. A merged vehicle that fails it is dropped, whatever its sources. Its score is
//     s = 1 - (1 - s_v) (1 - w c)
// with s_v the verification's score (sides over their threshold, times the shadow's depth: 0 for a
// vehicle without a shadow hypothesis), c the best appearance score (cascade) among its members
// (0: none) and w = appearance_weight: the cascade's evidence and the edges' combine as independent
// cues. Overlapping results are thinned as the shadow detector does (verify.nms_iou).
// A vehicle only the shadow detector found gets exactly the shadow detector's detection.
#pragma once

#include "base/params.hpp"
#include "detect/detector.hpp"
#include "detect/road_prior.hpp"
#include "detect/verify.hpp"

#include <vector>

namespace hw {

struct MergeParams {
    double bottom_tol = 0.25;        // widths; bottom rows at most this far apart can be one vehicle
    double span_iou = 0.5;           // 1-D IoU of the column spans, at least, for one vehicle
    double appearance_weight = 1.0;  // w: share of the cascade's score added as independent evidence
    double min_appearance = 1.0;     // a vehicle without a shadow edge, found by one detector: its cascade score, at least (1: never)
    int appearance_lanes = 4;        // lanes; such a vehicle stands on the ego lane or at most this many lanes beside it

    void bind(ParamMap &m) {
        m.add("bottom_tol", bottom_tol, 0.0, 2.0,
              "vehicle widths; hypotheses of several detectors whose bottom rows are at most this far apart (and "
              "whose columns overlap by span_iou) are one vehicle, verified once");
        m.add("span_iou", span_iou, 0.05, 1.0,
              "IoU of the column spans [left, right] of two hypotheses, at least, for them to be one vehicle");
        m.add("appearance_weight", appearance_weight, 0.0, 1.0,
              "share w of a learned appearance score c (the cascade's) that raises a verified vehicle's score s_v: "
              "s = 1 - (1 - s_v)(1 - w c); 0 ignores the cascade's score");
        m.add("min_appearance", min_appearance, 0.0, 1.0,
              "a vehicle among whose hypotheses is no shadow edge and that one detector alone found (the cascade or "
              "the parallax difference) is kept only if its cascade score c reaches this (a parallax region alone has "
              "c = 0); two detectors agreeing, or a shadow edge, need no appearance; 0 keeps every verified vehicle");
        m.add("appearance_lanes", appearance_lanes, 0, 4,
              "lanes; a vehicle kept by min_appearance alone (no shadow edge, one detector) must stand on the ego lane "
              "or at most this many lane widths beside it (its bottom centre, the ego lane's width at that row; not "
              "checked without a lane model); 4: not narrower than the scan (shadow.adjacent_lanes 2). Preset "
              "cascade_shadow_phd sets 2: with 4 the cascade's boxes on the synthetic roadside bushes beyond the verge "
              "became vehicles, with 1 a pre-warning came back on solidWhiteRight (docs/RESULTS.md)");
    }
};

class HypothesisMerge {
public:
    // road: the expected vehicle width per row (the shadow detector's road prior, section shadow).
    HypothesisMerge(const MergeParams &merge, const VerifyParams &verify, const RoadPriorParams &road)
        : p_(merge), verify_(verify), road_(road) {}
    // The verified vehicles of the unverified hypotheses `raw` (any detectors'), strongest first.
    std::vector<Hypothesis> merge_and_verify(const RoadContext &ctx, const std::vector<Hypothesis> &raw) const;

private:
    MergeParams p_;
    VerifyParams verify_;
    RoadPriorParams road_;
};

} // namespace hw
