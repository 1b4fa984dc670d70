#include "track/vehicle_height.hpp"

#include "base/sections.hpp"
#include <algorithm>

namespace hw {

namespace {
// Whether the detection's measured top tells the vehicle's shape: not guessed, and its box not cut by a side of the
// image (then its width is only the visible part's).
bool shape_measured(const Hypothesis &d, int cols) {
    return d.top_measured && d.box.x >= 1.f && d.box.x + d.box.width <= float(cols) - 1.f;
}
bool measured_tall(const Hypothesis &d, const VehicleHeightParams &p) {
    return d.box.height > p.tall_aspect * d.box.width;
}
} // namespace

void VehicleHeight::start(const Hypothesis &d, int cols, const VehicleHeightParams &p) {
    aspect = d.box.height / std::max(1.f, d.box.width);
    tall_run = shape_measured(d, cols) && measured_tall(d, p) ? 1 : 0;
}

void VehicleHeight::take(const Hypothesis &d, int cols, double gain, const VehicleHeightParams &p) {
    if (!(d.box.width > 0.f)) return;
    const bool was_tall = tall(p);
    if (shape_measured(d, cols)) tall_run = measured_tall(d, p) ? tall_run + 1 : 0;
    // A height the verification only guessed (a car's aspect) says nothing of a truck's.
    if (d.top_measured || !was_tall)
        aspect = (1.0 - gain) * aspect + gain * d.box.height / std::max(1.f, d.box.width);
}

cv::Rect2f VehicleHeight::compared_box(const Hypothesis &d, const cv::Rect2f &vb, const VehicleHeightParams &p) const {
    const cv::Rect2f &b = d.box;
    if (!tall(p) || d.top_measured) return b;
    return {b.x, b.y + b.height - vb.height, b.width, vb.height};
}

namespace {

// Its section, handed to the trackers that keep a box height (kalman, phd: their `share`).
const bool registered = register_section<VehicleHeightParams>("vehicle_height");

} // namespace

} // namespace hw
