// dot_markings.hpp - Botts' dots: rows of raised dots as lane lines, found as dots lined up toward the horizon.
//
// Some roads (California's freeways in TuSimple's data) mark lane lines with raised dots about 0.1 m across,
// every 1-2 m in groups, instead of paint. At low resolution (512x288) a dot is a bright bar 1-3 px wide and
// 1-2 rows tall with a dark shadow under it: the marking filter drops it, being narrower than a painted line
// may be (marking_min_m) or alone on its row (min_run_rows), and loosening those bounds brings back as many
// specks of texture (TuSimple's 10-image lane sample). What tells a dot from a speck is not its
// own shape but its neighbours: the dots of a lane line lie on one image line through the vanishing point.
// So: the short bars the marking filter set aside (marking_filter.hpp, short_bars) are joined row to row
// into blobs; a blob a dot wide and short along the road (at range Z a length L spans L d^2 / (fy h) rows,
// d = y - y_h, road_geometry.hpp) is a dot candidate; a candidate is a dot when at least min_dots
// candidates (itself included), at least min_gap_m apart in range, lie within line_tol of a line through two of
// them that passes the expected vanishing point as a marking's line does (the Hough stage's wide window), and
// the candidates lie on the road (their surroundings as bright as the row's road, not a dark vehicle's body).
// The dots' bars then join the frame's marking points, so the Hough stage (wide consensus and narrow search),
// the lane assembly and the curve fit see a dotted line as a dashed one.
#pragma once

#include "base/params.hpp"
#include "geometry/camera.hpp"
#include "lanes/marking_filter.hpp"
#include "lanes/road_geometry.hpp"

#include <opencv2/core.hpp>

#include <vector>

namespace hw {

struct DotMarkingParams {
    bool enabled = true;           // look for Botts' dots among the short bars (one image)
    bool in_tracking = false;      // ... in lane tracking too
    double dot_m = 0.10;           // m; a dot's diameter (Botts' dots: 4 in)
    double max_length_m = 0.5;     // m; longest blob along the road taken as a dot (a dash is 3 m)
    double max_range_m = 40.0;     // m; farthest dots searched (beyond, a dot is under a pixel)
    double min_contrast = 10.0;    // gray levels; a dot's bar is this much brighter than its brighter side
    int min_dots = 4;              // dot candidates on one line (a group of Botts' dots is 4)
    double road_frac = 0.85;       // 1; the dot's surroundings at least this share of its row's median gray
    double min_gap_m = 0.6;        // m; range between two dots counted on one line (specks on one vehicle: once)
    double line_tol_frac = 0.004;  // fraction of the width; farthest a dot lies from the line of the others
    int max_candidates = 64;       // strongest candidates tested (cost bound: pairs x candidates)

    void bind(ParamMap &m) {
        m.add("dots_enabled", enabled,
              "look for Botts' dots among the bars the marking filter sets aside (too narrow, alone on their row) "
              "and keep those lined up toward the horizon, in single images (docs/lanes.md)");
        m.add("dots_in_tracking", in_tracking,
              "with dots_enabled, look for Botts' dots in lane tracking (video) too; off: a line next to a car "
              "turned into one on TuSimple's clips (docs/lanes.md)");
        m.add("dot_m", dot_m, 0.01, 1.0,
              "m; a Botts' dot's diameter (0.10 m, 4 in); a candidate bar may be 1.5 times this wide on the "
              "flat-road model at its row plus 2 px of blur");
        m.add("dot_max_length_m", max_length_m, 0.05, 5.0,
              "m; a candidate blob spans at most this length along the road (L d^2 / (fy h) rows, plus 2 of "
              "blur): a dot, not a dash (3 m) or a solid line, which the marking filter finds as lines");
        m.add("dot_max_range_m", max_range_m, 5.0, 200.0,
              "m; farthest range at which dots are searched; 40 m, where a 0.1 m dot is about a pixel at 512 wide");
        m.add("dot_min_contrast", min_contrast, 1.0, 255.0,
              "gray levels; a dot candidate's bar is this much brighter than its brighter side (the marking filter's "
              "min_bar_contrast is a lower bound: bars below it are not set aside)");
        m.add("dot_min_count", min_dots, 3, 100,
              "candidates; fewest on one line for them to be dots; 4, one group of Botts' dots: fewer line up by "
              "chance among texture specks");
        m.add("dot_road_frac", road_frac, 0.0, 2.0,
              "1; a dot candidate lies on the road: the brightest of the pixels 4 px left, right, above and below it "
              "is at least this share of its row's median gray; bright specks on a dark vehicle (lamps, trim) are "
              "not; 0 disables");
        m.add("dot_min_gap_m", min_gap_m, 0.0, 20.0,
              "m; candidates on one line count as dots only this far apart in range (Botts' dots are about a metre "
              "apart in a group): bright specks bunched on one vehicle (lamps, trim, a plate) count once");
        m.add("dot_line_tol_frac", line_tol_frac, 0.0005, 0.05,
              "fraction of the image width; farthest a dot may lie from the line through two others (2 px at "
              "512): dots sit on a straight line to a pixel over a few metres");
        m.add("dot_max_candidates", max_candidates, 4, 1024,
              "count; the strongest candidates (summed bar contrast) tested for alignment; bounds the cost, "
              "which grows as pairs x candidates");
    }
};

// The dots among `short_bars` (marking_filter.hpp; sorted by row) are appended to `points` (their bars, one
// per row, unless a marking point is already there), which stay sorted by row then column. vp_tol_px: farthest
// a dotted line may pass from the expected vanishing point (hp.vp_x, hp.row), as the Hough stage's wide window.
void add_dot_markings(const cv::Mat &gray, const std::vector<MarkingPoint> &short_bars, const ScanBand &band,
                      const CameraParams &cam, const HorizonPrior &hp, const DotMarkingParams &p, float vp_tol_px,
                      std::vector<MarkingPoint> &points);

} // namespace hw
