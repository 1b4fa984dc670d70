// vehicle_top.hpp - the top of a vehicle from how far up its sides reach.
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
//
// vehicle_top_between() is the same search with the bounds given as rows and a choice of sides: a
// vehicle cut by the image's side (entering, overtaking) shows only its inner side, and its visible
// width says nothing about its height, so the caller bounds the search by a height in metres on the
// flat road instead (detect/parallax/aligned_difference.cpp). snap_side() moves a side given to a few pixels (a region
// of the aligned difference, widened by the vehicle's cast shadow) onto the vertical edge it belongs to.
#pragma once

#include "geometry/vehicle_shape.hpp"

#include <opencv2/core.hpp>

#include <cmath>
#include <utility>

namespace hw {

struct TopSearch {
    // height / width bounds of the search (a lower top: the caller's fallback); the vehicle's (vehicle_shape)
    double min_aspect = VehicleShapeParams{}.top_min_aspect;
    double max_aspect = VehicleShapeParams{}.max_aspect;
    double keep_frac = 0.35;   // side edge strength, relative to the lower body, that still counts
    int max_gap = 2;           // rows; gaps bridged going up
};

// The rows [first, last] of a vehicle's lower body, above its wheels and underbody shadow (0.15 .. 0.45
// widths above its bottom): where its sides are measured as a reference.
inline std::pair<int, int> lower_body_rows(float bottom, float width) {
    return {int(std::lround(bottom - 0.45f * width)), int(std::lround(bottom - 0.15f * width))};
}

// Returns the top row (px) of the vehicle between sub-pixel sides `left`, `right` standing on
// `bottom`, or NaN when the side edges do not tell.
float vehicle_top(const cv::Mat &gray, float left, float right, float bottom, const TopSearch &p);

// The same search, the top looked for in rows [y_min, y_max] (y_max: the lowest top accepted) and
// followed along the left side, the right side or both (the weaker of the two per row); at least one.
// The lower body (reference strength) is taken 0.15 .. 0.45 of `ref_w` above the bottom.
float vehicle_top_between(const cv::Mat &gray, float left, float right, float bottom, float ref_w, int y_min,
                          float y_max, bool use_left, bool use_right, double keep_frac, int max_gap);

// The column (px, the centre between the two pixels of the step) of the strongest vertical edge within
// `radius` px of `x`, averaged over rows [y0, y1]; x itself when there is no such column or no edge.
float snap_side(const cv::Mat &gray, float x, int y0, int y1, float radius);

} // namespace hw
