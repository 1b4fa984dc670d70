// parallax/part.hpp - detector part "parallax" (paper 000): the previous frame's road band warped
// onto the current one with the road-motion stage's homography, and the regions of differences over the
// road area (aligned_difference.hpp) become hypotheses at their mid-lower point. Needs the road-motion
// stage; cannot run before it holds an estimate.
//
// The road area is the lane model's, widened to road_lanes_each_side lane widths beside the ego lane,
// stopped above the bonnet and continued toward the vanishing point up to road_range_m. A second
// difference is taken against the frame long_gap frames back, warped with the product of the filtered
// homographies since: long_gap times the parallax of a vehicle keeping its distance (far vehicles at
// 30 fps move a fraction of a pixel per frame; the paper ran at 5-10 fps); its regions count where the
// one-frame difference found none (fast vehicles smear over long gaps). The part keeps those bands
// itself (end_frame), every frame, whether or not the tracker asked for a detection.
#pragma once

#include "base/sections.hpp"
#include "detect/detector.hpp"
#include "detect/parallax/aligned_difference.hpp"

#include <deque>
#include <utility>
#include <vector>

namespace hw {

// Section "parallax": the parallax detector part and the road band the road-motion stage keeps for it.
struct ParallaxSection {
    ParallaxParams detect;
    double band_above_horizon = 0.08;  // share of the image height above the horizon kept in the road band
    double road_range_m = 120.0;       // m; the road area is continued toward the vanishing point up to here
    double road_lanes_each_side = 2.0; // lane widths; the road area covers at least the ego lane +- this
    bool exclude_vehicle_corners = true;  // road features inside confirmed vehicles' boxes are not used
    double max_dt_s = 1.0;             // s; a longer gap between frames starts everything again
    int long_gap = 3;                  // frames back of the second, long-gap difference (0, 1: none)
    double long_gap_min_range_m = 0.0;   // m; the long-gap difference covers the road beyond this range only (0: all)
    double search_max_speed_mps = 45.0;  // m/s; travel searched when there is no prediction
    int search_steps = 24;             // travels tried between 0 and that

    void share(const SectionLookup &c) { detect.shape = c.get<VehicleShapeParams>("vehicle_shape"); }
    void bind(ParamMap &m);
};
class ParallaxDifferenceDetector final : public Detector {
public:
    ParallaxDifferenceDetector(const ParallaxSection &p, const CameraParams &cam) : p_(p), cam_(cam) {}
    bool needs_road_motion() const override { return true; }
    bool detect(const RoadContext &ctx, std::vector<Hypothesis> &out, StageTimes &times) override;
    void end_frame(const RoadContext &ctx) override;
    void reset() override;
    // The last detection's regions (for the two-frame stages and evaluation).
    const ParallaxFrame &last() const { return last_; }

private:
    ParallaxSection p_;
    CameraParams cam_;
    std::deque<std::pair<cv::Mat, cv::Matx33d>> history_;  // older bands at the level, each with H to the next
    ParallaxFrame last_;
};

} // namespace hw
