// vehicle_top.hpp - the top of a verified vehicle from how far up its two sides reach.
//
// The thesis sets the top from a fixed aspect ratio ("no consistent cue marks the top"), which is
// right for cars and far off for vans and trucks. Both sides of a vehicle are vertical edges from
// its bottom up to its roof; above the roof the background rarely continues both at once. So, going
// up from the lower part of the body, the top is the last row at which both side columns still
// carry a vertical edge of at least `keep_frac` of their typical strength on the lower body
// (short gaps of `max_gap` rows bridged: a window frame, a seam), provided a horizontal edge (the
// roof line) closes the sides there. The result is kept within
// [min_aspect, max_aspect] times the width; when the sides are too weak to say, the caller's
// fallback aspect applies.
#pragma once

#include <opencv2/core.hpp>

namespace hw {

struct TopSearch {
    double min_aspect = 0.9;   // height / width bounds of the search (cars: the fixed aspect)
    double max_aspect = 1.6;
    double keep_frac = 0.35;   // side edge strength, relative to the lower body, that still counts
    int max_gap = 2;           // rows; gaps bridged going up
};

// Returns the top row (px) of the vehicle between sub-pixel sides `left`, `right` standing on
// `bottom`, or NaN when the side edges do not tell.
float vehicle_top(const cv::Mat &gray, float left, float right, float bottom, const TopSearch &p);

} // namespace hw
