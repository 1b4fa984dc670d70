// kalman/roi_search.hpp - re-finding a tracked vehicle around its predicted bottom corners (thesis 3.6.1).
//
// Bottom: project the shadow edges (bright road below, dark shadow above) of the vehicle's inner
// columns onto the rows inside the Kalman gate around the predicted bottom row; the largest value
// is the bottom edge. Sides: project the vertical edges of an ROI standing on that bottom, widened
// by the gate, onto the columns and apply the two-threshold rule (half the largest value first; the
// largest value itself if a side would jump more than the largest change seen so far). The
// measurement is accepted only with a clear bottom edge, two sides that stand out against the road,
// and a width close to the predicted one.
#pragma once

#include "cues/road_prior.hpp"
#include "cues/shadow.hpp"
#include "cues/verify.hpp"

namespace hw {

// Where to look: the predicted bottom corners and the gate half-widths (px) around them.
struct RoiPrediction {
    float x1 = 0.f, y1 = 0.f, x2 = 0.f;
    float gate_x = 0.f, gate_y = 0.f;
    float sigma_x = 1.f;          // innovation standard deviation of a side column (px)
    float max_side_change = 0.f;  // two-threshold rule: largest accepted side change so far (px)
};

struct RoiSearchParams {
    double bottom_min_frac = 0.5;    // bottom edge profile / step threshold, at least
    double max_scale_change = 0.25;  // |measured width / predicted width - 1|, at most
};

struct RoiMeasurement {
    bool found = false;
    float x1 = kNaN, y1 = kNaN, x2 = kNaN;
    float side_excess = 0.f;  // weaker side / side threshold (>= 1 when found)
    float road_gray = kNaN;
};

// edge: what a shadow edge is (the bottom); verify: the ROI around it and the side threshold (margin_px,
// margin_frac, roi_height_frac, side_rel, side_min_gray).
RoiMeasurement search_roi(const cv::Mat &gray, const RoiPrediction &pred, const ShadowEdgeParams &edge,
                          const VerifyParams &verify, const RoiSearchParams &p);

// The search above as the Kalman tracker is handed it, from shared units' sections only: the shadow edge
// (section shadow_edge) and the verification's side rule (section verify) that the shadow detector uses too, so
// the tracker re-finds its vehicles by the edges the detector finds them by; and the width a vehicle has at a row
// (the road prior's, from sections road and vehicle_shape).
class RoiSearch {
public:
    // prior: its lane and vehicle widths, the only fields expected_vehicle_width reads (RoadPriorParams::share)
    RoiSearch(const ShadowEdgeParams &edge, const VerifyParams &verify, const RoadPriorParams &prior)
        : edge_(edge), verify_(verify), prior_(prior) {}
    RoiMeasurement search(const cv::Mat &gray, const RoiPrediction &pred, const RoiSearchParams &p) const {
        return search_roi(gray, pred, edge_, verify_, p);
    }
    // Expected image width of a vehicle whose bottom is at row y (0 when no vehicle stands there).
    float expected_width(float y, cv::Size size, const LaneModel &lanes, const CameraParams &cam) const;
    double vehicle_width_m() const { return prior_.shape.width_m; }  // m (section vehicle_shape)

private:
    ShadowEdgeParams edge_;
    VerifyParams verify_;
    RoadPriorParams prior_;
};

// Gray level of the road right below a bottom edge (median of a strip under [x1, x2]); NaN if the
// strip lies outside the image.
float road_gray_below(const cv::Mat &gray, float x1, float y1, float x2);

} // namespace hw
