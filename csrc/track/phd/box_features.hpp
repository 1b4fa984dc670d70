// phd/box_features.hpp - corner points inside a vehicle's box, and their frame-to-frame motion.
//
// Corners: Shi-Tomasi (min eigenvalue of the structure tensor), Harris (det - k trace^2) or FAST,
// the strongest ones at least min_distance apart, found only in the inner part of the box (its
// border holds road and background). Motion: pyramidal Lucas-Kanade from the previous frame to this
// one and back (forward-backward check, Kalal 2010): a point that does not come back within fb_max_px
// of where it started was not followed and is dropped. One LK call follows every vehicle's points, on the
// pyramids of the region they lie in.
#pragma once

#include "base/params.hpp"

#include <opencv2/core.hpp>

#include <vector>

namespace hw {

struct BoxFeatureParams {
    std::string detector = "shi_tomasi";  // shi_tomasi | harris | fast
    int max_per_vehicle = 24;             // corners looked for in one box
    double quality = 0.02;                // Shi-Tomasi/Harris: fraction of the strongest response
    int fast_threshold = 12;              // FAST: gray-level difference on the circle
    double min_distance_px = 3.0;         // px; between two corners (and from existing features)
    double inner_margin_frac = 0.1;       // box fraction left out at each side and the top
    double bottom_margin_frac = 0.15;     // box fraction left out at the bottom (shadow, road)
    int lk_window_px = 9;                 // px; LK window side
    int lk_levels = 2;                    // pyramid levels above the full frame
    int lk_iterations = 10;               // LK iterations per level
    double fb_max_px = 1.0;               // px; forward-backward disagreement above which a point is lost
    int roi_margin_px = 24;               // px; around the points, the region whose pyramids LK works on

    void bind(ParamMap &m);
};

// Corners inside the inner part of `box`, none within min_distance_px of `existing`.
std::vector<cv::Vec2d> box_corners(const cv::Mat &gray, const cv::Rect2f &box, const std::vector<cv::Vec2d> &existing,
                                   const BoxFeatureParams &p);

// FAST corners of an image (non-maximum suppressed), strongest response first; points in its coordinates.
std::vector<cv::Point2f> fast_corners_strongest_first(const cv::Mat &gray, int threshold);

// LK with the forward-backward check between consecutive frames. Only the region the points can reach is
// looked at: the bounding box of the points plus `roi_margin_px` (the largest motion followed, plus the LK
// window at the coarsest level), the same rectangle in both frames, and the pyramids of that rectangle
// alone are built (the whole 640x480 frame's pyramid was most of the tracker's cost, docs/tracking.md).
class PointFlow {
public:
    explicit PointFlow(const BoxFeatureParams &p) : p_(p) {}
    // The new frame: it becomes the current one, the previous one is kept (a reference to the caller's
    // buffer is not: the frame is copied).
    void next_frame(const cv::Mat &gray);
    bool ready() const { return !prev_.empty() && !cur_.empty(); }
    // Tracks `pts` (previous frame) into the current one; ok[i] false where the point was lost.
    void track(const std::vector<cv::Point2f> &pts, std::vector<cv::Point2f> &out, std::vector<uchar> &ok) const;
    void reset() { prev_.release(); cur_.release(); }

private:
    BoxFeatureParams p_;
    cv::Mat prev_, cur_;
};

} // namespace hw
