// dark_markings.hpp - an adjacent lane line seen darker than the road (a concrete joint, dark dots on it).
//
// On concrete freeways the slabs are joined along the lane lines, and Botts' dots sit on the joint: at low
// resolution (512x288) such a lane line is often a narrow band darker than the road (the joint's sealant, the
// dots' shadows, dirt in the groove: 0313-2/37400's left adjacent line 100-120 gray against a road of 140-160),
// which the marking filter, a bright-bar filter, cannot see. A dark band is no evidence on its own (tyre tracks,
// cracks, shadows of poles), so it is only looked for where the road's geometry puts a lane line: one image
// alone, an ego pair found and the adjacent boundary on one side missing. On the flat road every marking is
// x(d) = a + b d + c / d (lane_curve.hpp) with one a and one c, so the line s lane widths out from the ego lane
// is x_side(y) -+ s (x_right(y) - x_left(y)), whatever the curve; s is searched near 1 (adjacent lanes are about
// as wide as the ego lane) and the line is kept when enough dark bars of a marking's width (the marking filter
// on the inverted image) lie along it, the new boundary passing through them (least squares in s).
#pragma once

#include "base/params.hpp"
#include "base/types.hpp"
#include "geometry/camera.hpp"
#include "lanes/marking_filter.hpp"
#include "lanes/road_geometry.hpp"

#include <opencv2/core.hpp>

#include <vector>

namespace hw {

struct DarkLineParams {
    bool enabled = true;          // look for a missing adjacent boundary as a dark line (one image)
    double width_tol = 0.15;      // ego-lane widths; the adjacent lane is 1 +- this ego lane wide
    int min_rows = 12;            // scanned rows; fewest rows with a dark bar on the line (curve_min_points)
    double corridor_lanes = 0.06; // lane widths; a dark bar farther than this from the line is not its
    double road_frac = 0.85;      // 1; both sides of a dark bar within this share (and its inverse) of the road

    void bind(ParamMap &m) {
        m.add("dark_adjacent", enabled,
              "one image alone, an ego pair found and one adjacent boundary missing: look for it as a narrow dark "
              "line one lane width out (a concrete joint; docs/lanes.md)");
        m.add("dark_width_tol", width_tol, 0.0, 1.0,
              "ego-lane widths; the dark line is searched 1 +- this ego-lane widths out from the ego boundary (0.15 "
              "allows 3.6 +- 0.55 m lanes)");
        m.add("dark_min_rows", min_rows, 2, 1000,
              "scanned rows; fewest rows holding a dark bar of a marking's width on the line for it to be a "
              "boundary (as curve_min_points)");
        m.add("dark_corridor_lanes", corridor_lanes, 0.01, 0.5,
              "lane widths; a dark bar belongs to the line within this distance of it (at least 1.5 px); half the "
              "curve fit's corridor (curve_corridor_lanes): the line has one unknown, its spacing; 0.03-0.10 read the "
              "same on the sample");
        m.add("dark_road_frac", road_frac, 0.0, 1.0,
              "1; a dark bar lies on the road: both its sides at least this share of the ego lane's median gray on "
              "its row and at most its inverse (not a vehicle's tyres or trim)");
    }
};

// m: one image's model after the curve fit. Where m is valid and adj_left (adj_right) is not, the dark line
// about one lane width left (right) of the ego lane, if found, becomes adj_left (adj_right).
void add_dark_adjacent(const cv::Mat &gray, const ScanBand &band, const CameraParams &cam, const HorizonPrior &hp,
                       const MarkingFilterParams &filter, const DarkLineParams &p, LaneModel &m);

} // namespace hw
