// edge_projection.hpp - edge projections inside a region of interest, and the thesis's rules for
// finding a vehicle's sides and bottom in them (thesis 2.4.2.2 and 3.6.1).
//
// Vertical edges (the sides) are projected onto the columns:
//     w(x) = 1/(4 n) * sum_{y in ROI} |S_x(x, y)|                  (S_x: 3x3 Sobel, gain 4)
// and shadow edges (the bottom) onto the rows, bright road below and dark shadow above only:
//     v(y) = 1/(4 m) * sum_{x in ROI} max(0, S_y(x, y))
// Both are mean gray-level steps, so thresholds can be stated against the road's gray level.
#pragma once

#include <opencv2/core.hpp>

#include <vector>

namespace hw {

// w(x) for the columns of `roi` (clipped to the image by the caller).
std::vector<float> vertical_edge_profile(const cv::Mat &gray, const cv::Rect &roi);
// v(y) for the rows of `roi`, counting only pixels whose upper neighbour is at most `dark`.
std::vector<float> shadow_edge_profile(const cv::Mat &gray, const cv::Rect &roi, int dark);

// Index of the largest value of v in [from, to) (from if the range is empty).
int argmax(const std::vector<float> &v, int from, int to);

// Sub-pixel position of the peak at index i: the vertex of the parabola through v[i-1], v[i], v[i+1]
//     i + (v[i-1] - v[i+1]) / (2 (v[i-1] - 2 v[i] + v[i+1]))
// (i itself at the ends or on a plateau). An edge between pixels k and k+1 makes equal responses at
// k and k+1 and lands at k + 0.5, the boundary in pixel-centre coordinates.
float peak_position(const std::vector<float> &v, int i);

// Two sides as indices into a column profile, with their profile values.
struct SidePair {
    int left = -1, right = -1;
    float left_strength = 0.f, right_strength = 0.f;
    bool found() const { return left >= 0 && right > left; }
    float weaker() const { return std::min(left_strength, right_strength); }
};

// Detection rule (thesis 2.4.2.2, with the outer-edge choice of 3.6.1): in each part of the profile
// split at `split`, the outermost column reaching half of that part's largest value. A vehicle's outer
// edge is not always its strongest one (tail lights, a van's door seams); the outermost clear edge is.
SidePair outer_sides(const std::vector<float> &w, int split);

// The profile weighted by a Gaussian prior around the expected left and right side columns:
//     w'(x) = w(x) exp(-(x - c)^2 / (2 sigma^2)),  c = left for x < (left + right) / 2, else right
// so that a neighbour's edge a few sigma away cannot outweigh the vehicle's own side.
std::vector<float> side_prior(const std::vector<float> &w, float left, float right, float sigma);

// Long-shadow rule: the pair of columns with separation in [min_sep, max_sep] whose weaker side is
// strongest (the vehicle stands over part of a shadow that is wider than itself).
SidePair best_side_pair(const std::vector<float> &w, int min_sep, int max_sep);

// Tracking rule (thesis 3.6.1), inside a window of +-`window` columns around each predicted side
// (the Kalman gate: a neighbour's edge elsewhere in the ROI cannot take a side): search each window
// from its outer end for the first column reaching half the largest value in the windows; if that
// moves a side more than `max_change` from its prediction, take the largest value of its window.
SidePair two_threshold_sides(const std::vector<float> &w, int pred_left, int pred_right, int window,
                             float max_change);

} // namespace hw
