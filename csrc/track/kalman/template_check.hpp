// kalman/template_check.hpp - "is the vehicle still there?" by normalised correlation (thesis 3.6).
//
// Before a vehicle that the edge search did not re-find is dropped, the thesis correlates the
// image region of its last box with the same region now; a high normalised correlation means the
// vehicle is probably still there. Here the region may also shift by a few pixels (the vehicle
// moved since its last box), and the best shift is returned so that the tracker can use it as a
// weak measurement. Both patches are scaled down to at most `template_px` columns, which bounds the
// cost whatever the vehicle's size:
//     NCC(u, v) = sum (T - mean T)(I_uv - mean I_uv) / sqrt(sum (T - mean T)^2 sum (I_uv - mean I_uv)^2)
#pragma once

#include <opencv2/core.hpp>

namespace hw {

// A vehicle's appearance at its last measurement.
struct VehicleTemplate {
    cv::Mat patch;       // CV_8UC1, scaled by `scale`
    cv::Rect2f box;      // where it was, full-resolution px
    float scale = 1.f;   // patch px per image px
    bool usable() const { return !patch.empty(); }
};

// Cuts the template for `box` out of `gray`; an empty template if the box is mostly outside the
// image or too flat to correlate (standard deviation below min_std_gray).
VehicleTemplate make_template(const cv::Mat &gray, const cv::Rect2f &box, int template_px, double min_std_gray);

struct TemplateMatch {
    float ncc = -1.f;           // best normalised correlation, -1 if not computed
    cv::Point2f shift{0.f, 0.f};  // image px from `at` to the best match
};

// Best NCC of the template against `gray` for the template's box moved to `at` (same size), over
// shifts of up to search_px image pixels in each direction.
TemplateMatch match_template(const cv::Mat &gray, const VehicleTemplate &t, const cv::Rect2f &at, float search_px);

} // namespace hw
