// lane_features.hpp - road-plane point correspondences between two frames, taken on the lane
// markings (paper 000, section II-A).
//
// 1. Row filter. Each row j of the road band is filtered as
//        y_i = 2 x_i - (x_{i-t} + x_{i+t}) - |x_{i-t} - x_{i+t}|          (paper eq. 1)
//    which equals 2 (x_i - max(x_{i-t}, x_{i+t})): high only where x_i is brighter than both
//    neighbours at distance t, and penalised where those neighbours differ (a vehicle-to-road step,
//    a shadow edge). t(j) shrinks toward the vanishing point with the marking width the flat-road
//    model expects at that row: t(j) = max(t_min, t_factor * w_m * fx (j - y_h) / (fy h)).
// 2. The thresholded response goes to a probabilistic Hough transform; the segments are clustered
//    into markings (both end points near the line of the cluster's longest segment), and each
//    marking is represented by its mean segment s_i = (mean lower end, mean upper end).
// 3. A search region is grown around each mean segment: along its line beyond the cluster's rows
//    and across it to a few marking widths, so that it holds the whole marking.
// 4. Harris corners inside the regions (the ends of the dashes, mostly).
// 5. Pyramidal Lucas-Kanade finds each corner in the previous frame, starting from where the
//    predicted homography puts it; a forward-backward check (previous -> current must come back
//    within fb_max_px) drops corners that slid along a marking or were hidden.
#pragma once

#include "core/params.hpp"
#include "core/types.hpp"
#include "geometry/camera.hpp"

#include <opencv2/core.hpp>

#include <vector>

namespace hw {

struct LaneFeatureParams {
    double marking_width_m = 0.15;   // m; painted line width the row filter is sized for
    double t_factor = 1.5;           // t(j) in marking widths
    int t_min_px = 2;                // px; smallest t near the vanishing point
    double response_min = 24.0;      // gray levels; eq. 1 response kept (= 12 levels above the brighter side)
    double max_range_m = 50.0;       // m; farthest road row filtered
    int hough_threshold = 15;        // votes
    int hough_min_length_px = 12;    // px
    int hough_max_gap_px = 4;        // px
    double min_angle_deg = 12.0;     // deg from horizontal; flatter segments are not markings
    double cluster_tol_px = 5.0;     // px; segment ends this near a marking's line join it
    int max_markings = 8;            // clusters kept (most supported first)
    double grow_along = 0.5;         // region extends this share of the marking's row span beyond it
    double grow_across = 3.0;        // region half-width in marking widths
    int grow_min_px = 4;             // px; smallest region half-width
    int max_corners = 150;           // Harris corners at most
    double harris_quality = 0.01;    // fraction of the strongest corner
    double harris_k = 0.04;          // Harris free parameter
    int min_corner_distance_px = 5;  // px
    int lk_window_px = 15;           // px; Lucas-Kanade window side
    int lk_levels = 3;               // pyramid levels above the base
    double fb_max_px = 0.7;          // px; forward-backward error kept

    void bind(ParamMap &m);
};

// A road point seen in both frames.
struct Correspondence {
    cv::Point2f prev, cur;
};

// One lane marking: its mean Hough segment and its search region.
struct MarkingSegment {
    cv::Point2f lower, upper;          // mean segment end points (lower = larger row)
    int segments = 0;                  // Hough segments in the cluster
    std::vector<cv::Point> region;     // convex search region (4 corners)
};

// Everything the unit found in one frame (kept for tests, drawing and counting).
struct LaneFeatures {
    std::vector<MarkingSegment> markings;
    std::vector<cv::Point2f> corners;          // Harris corners in the current frame
    std::vector<Correspondence> matches;       // corners that passed LK and the forward-backward check
};

// The rows the row filter scans: from max_range_m (for the horizon row y_h) to the bottom.
cv::Range lane_feature_rows(int height, float horizon_row, const CameraParams &cam, const LaneFeatureParams &p);

// Eq. 1 on every row of `rows`, thresholded: 255 where y_i >= response_min (CV_8UC1, full size).
void marking_response(const cv::Mat &gray, cv::Range rows, float horizon_row, const CameraParams &cam,
                      const LaneFeatureParams &p, cv::Mat &binary);

// Hough segments of the binary response clustered into markings, with their search regions.
std::vector<MarkingSegment> marking_segments(const cv::Mat &binary, cv::Range rows, float horizon_row,
                                             const CameraParams &cam, const LaneFeatureParams &p);

// The lane-feature tracker: keeps the previous frame's pyramid.
class LaneFeatureTracker {
public:
    explicit LaneFeatureTracker(const LaneFeatureParams &p) : p_(p) {}

    // Builds this frame's pyramid and, if a previous frame is held, finds correspondences.
    // H_guess maps previous -> current pixels (the predicted homography); identity if unknown.
    // horizon_row: the row of the road's vanishing point.
    void process(const cv::Mat &gray, float horizon_row, const CameraParams &cam, const cv::Matx33d &H_guess,
                 LaneFeatures &out);
    bool has_previous() const { return !prev_pyr_.empty(); }
    void reset() { prev_pyr_.clear(); }

private:
    LaneFeatureParams p_;
    std::vector<cv::Mat> prev_pyr_;
    cv::Mat binary_;  // scratch
};

} // namespace hw
