// homography_dlt.hpp - the plane homography from point correspondences: normalised DLT
// (Hartley & Zisserman, algorithm 4.2), with one trimming pass.
//
// For x' ~ H x, each correspondence gives two rows of A h = 0 (h = H row-major):
//     [ 0 0 0   -x -y -1   y'x y'y y' ]
//     [ x y 1    0  0  0  -x'x -x'y -x' ]
// Both point sets are first normalised (centroid to the origin, mean distance sqrt 2) so that A is
// well conditioned; h is the eigenvector of A^T A with the smallest eigenvalue, and
// H = T'^-1 H_n T. The paper relies on its Kalman gate rather than robust estimation. Two cheap
// guards are added, because a wrong correspondence far from the others (a near dash end matched to
// the next dash, 12 m on) has so much leverage that the DLT fits it exactly and spoils the rest:
// correspondences farther than point_gate_px from where the predicted homography puts them are
// dropped first (when a prediction exists), and one trimming pass refits without those whose
// transfer error is far above the median. Without a prediction (the first frames, no ego speed)
// nothing tells a near dash end from the next dash 12 m on, so the inliers of a RANSAC homography
// (OpenCV's, minimal DLT samples) take the place of the prediction gate.
#pragma once

#include "base/params.hpp"

#include <opencv2/core.hpp>

#include <vector>

namespace hw {

struct DltParams {
    int min_points = 8;            // correspondences needed for a measurement
    double point_gate_px = 3.0;    // px; farthest a correspondence may be from the prediction (0: no gate)
    double min_row_span_px = 40.0; // px; the points must spread over this many rows
    double trim_factor = 3.0;      // transfer errors above this many medians are trimmed (0: no trimming)
    double trim_floor_px = 1.0;    // px; never trim below this transfer error
    double max_rms_px = 2.5;       // px; a fit with a larger rms transfer error is no measurement
    double ransac_px = 2.0;        // px; RANSAC inlier distance when there is no prediction

    void bind(ParamMap &m);
};

struct HomographyFit {
    bool ok = false;
    cv::Matx33d H = cv::Matx33d::eye();  // from -> to, H(2,2) = 1
    int used = 0;                         // correspondences in the final fit
    double rms_px = 0.0;                  // rms transfer error of the used correspondences
};

// Plain normalised DLT over the given points (>= 4, not checked for degeneracy). H(2,2) = 1.
cv::Matx33d normalised_dlt(const std::vector<cv::Point2f> &from, const std::vector<cv::Point2f> &to);

// |to - H from| for one correspondence.
double transfer_error(const cv::Matx33d &H, cv::Point2f from, cv::Point2f to);

// DLT with the checks, the prediction gate and the trimming pass of DltParams. predicted: the
// predicted homography from -> to, or null when there is none.
HomographyFit fit_homography(const std::vector<cv::Point2f> &from, const std::vector<cv::Point2f> &to,
                             const DltParams &p, const cv::Matx33d *predicted = nullptr);

} // namespace hw
