// lane_features.hpp - road-plane point correspondences between two frames, taken on the lane
// markings (paper 000, section II-A).
//
// 1. Row filter. Each row j of the road band is filtered as
//        y_i = 2 x_i - (x_{i-t} + x_{i+t}) - |x_{i-t} - x_{i+t}|          (paper eq. 1)
//    which equals 2 (x_i - max(x_{i-t}, x_{i+t})): high only where x_i is brighter than both
//    neighbours at distance t, and penalised where those neighbours differ (a vehicle-to-road step,
//    a shadow edge). t(j) shrinks toward the vanishing point with the marking width the flat-road
//    model expects at that row: t(j) = max(t_min, t_factor * w_m * fx (j - y_h) / (fy h)).
//    Each run of the thresholded response is reduced to its centre pixel (the marking's centre
//    line), so the Hough transform costs in proportion to the markings' length, not their area,
//    and runs narrower than min_run_frac of the marking width (texture specks) are dropped.
// 2. The thresholded response goes to a probabilistic Hough transform; segments whose line misses
//    the road's vanishing point by more than vp_tol_px are not markings; the rest are clustered
//    into markings (both end points near the line of the cluster's longest segment), and each
//    marking is represented by its mean segment s_i = (mean lower end, mean upper end).
// 3. A search region is grown around each mean segment: along its line over the whole road band
//    and across it to a few marking widths, so that it holds the whole marking (every dash).
// 4. Harris corners inside the regions (the ends of the dashes, mostly): the structure tensor is
//    computed only on the region pixels (3x3 Sobel, 3x3 window, R = det M - k tr^2 M), local maxima
//    above harris_quality of the strongest, strongest first with a minimum distance.
// 5. Pyramidal Lucas-Kanade finds each corner in the previous frame. Near the camera the road
//    grows by 10-15 % between frames, which biases a translation-only LK by a pixel or more, and
//    such a bias at the few near points tilts the whole homography. So the previous frame is first
//    warped around each corner by the local affine map of the predicted homography (a patch of
//    lk_patch_px), which leaves only the prediction's error to find: LK runs between the current
//    patch and the pre-warped one, and the found offset d maps back as g + J d (g the predicted
//    position, J the Jacobian of H_pred^-1 at the corner). A forward-backward check (the found
//    point tracked back must land within fb_max_px of the corner) drops corners that slid along a
//    marking or were hidden.
#pragma once

#include "base/params.hpp"
#include "base/types.hpp"
#include "geometry/camera.hpp"

#include <opencv2/core.hpp>

#include <vector>

namespace hw {

struct LaneFeatureParams {
    double marking_width_m = 0.15;   // m; painted line width the row filter is sized for
    double t_factor = 1.5;           // t(j) in marking widths
    int t_min_px = 2;                // px; smallest t near the vanishing point
    double response_min = 40.0;      // gray levels; eq. 1 response kept (= 20 levels above the brighter side)
    double min_run_frac = 0.3;       // response runs narrower than this share of the marking width are dropped
    double max_range_m = 50.0;       // m; farthest road row filtered
    int hough_threshold = 8;         // votes
    int hough_min_length_px = 8;     // px
    int hough_max_gap_px = 4;        // px
    double min_angle_deg = 12.0;     // deg from horizontal; flatter segments are not markings
    double vp_tol_px = 40.0;         // px; a segment's line must pass this near the vanishing point (0: no check)
    double cluster_tol_px = 5.0;     // px; segment ends this near a marking's line join it
    int max_markings = 8;            // clusters kept (most supported first)
    double grow_across = 1.0;        // region half-width in marking widths
    int grow_min_px = 4;             // px; smallest region half-width
    int grow_max_px = 20;            // px; largest region half-width
    int max_corners = 50;            // Harris corners at most
    double harris_quality = 1e-5;    // fraction of the strongest corner
    double harris_k = 0.04;          // Harris free parameter
    int min_corner_distance_px = 5;  // px
    int lk_window_px = 11;           // px; Lucas-Kanade window side
    int lk_levels = 1;               // pyramid levels above the base
    int lk_patch_px = 31;            // px; side of the pre-warped patch (window + the prediction's error)
    int lk_search_patch_px = 121;    // px; patch side without a prediction (first frames, after a loss)
    int lk_search_levels = 3;        // pyramid levels then
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

// Eq. 1 on every row of `rows`, thresholded, each run reduced to its centre: 255 there (CV_8UC1, full size).
void marking_response(const cv::Mat &gray, cv::Range rows, float horizon_row, const CameraParams &cam,
                      const LaneFeatureParams &p, cv::Mat &binary);

// Hough segments of the binary response clustered into markings, with their search regions.
// vp: the road's vanishing point (segments must point at it).
std::vector<MarkingSegment> marking_segments(const cv::Mat &binary, cv::Range rows, cv::Point2f vp,
                                             const CameraParams &cam, const LaneFeatureParams &p);

// Harris corners of `gray` on the non-zero pixels of `mask` within `rows`, strongest first.
std::vector<cv::Point2f> harris_corners(const cv::Mat &gray, const cv::Mat &mask, cv::Range rows,
                                        const LaneFeatureParams &p);

// Lucas-Kanade correspondences of `corners` (current frame) in the previous frame, on patches
// pre-warped with H_guess (previous -> current pixels), forward-backward checked. predicted: H_guess is
// a real prediction; otherwise (identity, first frames) larger patches and more levels search for
// the motion a car at speed gives near the camera.
std::vector<Correspondence> patch_lk(const cv::Mat &cur, const cv::Mat &prev, const std::vector<cv::Point2f> &corners,
                                     const cv::Matx33d &H_guess, bool predicted, const LaneFeatureParams &p);

// The whole unit on two frames: markings of `cur`, their corners, and the corners' correspondences
// in `prev`. vp: the road's vanishing point in `cur`; H_guess: predicted homography prev -> cur.
LaneFeatures lane_correspondences(const cv::Mat &cur, const cv::Mat &prev, cv::Point2f vp, const CameraParams &cam,
                                  const cv::Matx33d &H_guess, bool predicted, const LaneFeatureParams &p);

} // namespace hw
