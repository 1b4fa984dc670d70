// phd/scene_pitch.hpp - the horizon row frame by frame from the far scene's vertical image motion (the car's
// pitch), blended with the lane horizon for the slow part (the phd tracker's horizon).
//
// A bump, a sag or braking turns the camera by a fraction of a degree within a few frames: every far point
// then moves by the same number of rows, the vehicles ahead included, and a horizon that does not follow
// reads the vehicles' row motion as range (dZ = Z^2 / (fy h) per px: 1.2 m per px at 50 m on TME tme08, where
// a 9 px pitch swing in 0.25 s gave a range rate of -13 m/s to a car keeping its distance; docs/RESULTS.md).
// The lane vanishing point measures the horizon only as far as the near lane markings show it (on tme08 it
// followed 2 of those 9 px). Near the horizon row the car's own forward motion moves points by
// (v - v_h) V dt / Z, nothing at the horizon itself: corners in a band around it, outside every vehicle's box,
// are followed (LK with the forward-backward check) and the line dy = p + e (v - v_h) through their vertical
// shifts gives the pitch shift p, its value at the horizon row (robust least squares).
// Complementary filter, the fast part from the scene and the slow part from the lanes:
//     h_k = h_{k-1} + dy_k + g (l_k - h_{k-1} - dy_k),   l_k: the lane horizon (geometry/horizon.hpp)
// and h_k = l_k whenever fewer than min_points were followed (a bare sky and road: the lanes alone).
#pragma once

#include "base/params.hpp"
#include "track/phd/box_features.hpp"

#include <opencv2/core.hpp>

#include <vector>

namespace hw {

struct ScenePitchParams {
    bool enabled = true;            // follow the far scene's vertical motion (false: the lane horizon alone)
    double band_above_px = 30.0;    // px; rows above the horizon searched for far corners
    double band_below_px = 12.0;    // px; rows below it (the road there is > 150 m away at fy h = 2000 px m)
    int max_points = 60;            // corners followed per frame
    int min_points = 8;             // fewer followed: no scene measurement this frame
    double lane_gain = 0.1;         // g, 1/frame; pull towards the lane horizon (time constant 1/g frames)
    double max_offset_px = 25.0;    // px; the scene's horizon stays this close to the lane horizon

    void bind(ParamMap &m);
};

class ScenePitch {
public:
    explicit ScenePitch(const ScenePitchParams &p, const BoxFeatureParams &lk) : p_(p), lk_(lk) {}
    // The horizon row for the frame now in `flow` (whose previous frame is the last call's), given the lane
    // horizon of this frame and the vehicles' boxes (left out of the search).
    double update(const cv::Mat &gray, const PointFlow &flow, double lane_horizon, const std::vector<cv::Rect2f> &boxes);
    void reset() { started_ = false; prev_pts_.clear(); }
    int followed() const { return followed_; }  // points followed in the last frame

private:
    double pitch_shift(const std::vector<double> &dy, const std::vector<double> &r) const;

    ScenePitchParams p_;
    BoxFeatureParams lk_;
    std::vector<cv::Point2f> prev_pts_;  // corners found in the previous frame
    double row_ = 0.0;
    bool started_ = false;
    int followed_ = 0;
};

} // namespace hw
