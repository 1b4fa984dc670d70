// marking_filter.hpp - lane-marking points from row filtering (thesis: masks [-1 0 1] / [1 0 -1]).
//
// The thesis filters each row with [-1 0 1] (dark-to-bright transitions) or [1 0 -1] (bright-to-dark)
// so that only one edge of each marking responds, and feeds that to the Hough transform. Here both
// responses are computed from the same row difference, and a marking point is kept only where a
// dark-to-bright edge is followed, within the marking width the flat-road model allows at that row,
// by a bright-to-dark edge, with the bar between them brighter than both sides. The point is the
// middle of the bar: the marking centre, which is what the lane boundary means, and shadow edges,
// tar seams and vehicle outlines (single steps or wide bright areas) give no point at all.
#pragma once

#include "base/params.hpp"
#include "geometry/camera.hpp"
#include "lanes/road_geometry.hpp"

#include <opencv2/core.hpp>

#include <vector>

namespace hw {

struct MarkingFilterParams {
    double min_edge_contrast = 8.0;  // gray levels; [-1 0 1] response of a marking edge
    double noise_factor = 3.0;       // edge threshold >= this times the row's mean |response|
    double min_bar_contrast = 10.0;  // gray levels; marking brighter than both sides by at least this
    double min_bar_ratio = 0.08;     // marking brighter than its brighter side by this fraction
    double marking_min_m = 0.08;     // m; narrowest marking (thin lines, Botts' dots)
    double marking_max_m = 0.45;     // m; widest marking (wide edge lines, double lines merged)
    double max_range_m = 60.0;       // m; farthest road range scanned (markings beyond are a few px)
    int max_scan_rows = 200;         // rows; at most this many rows are filtered (cost bound)
    int min_run_rows = 2;            // scanned rows; a marking point needs neighbours to make a run this long
    int work_width_px = 640;         // px; wider rows are block-averaged down to about this width
    bool cross_inner_edges = true;   // a bar may contain weaker inner edges (worn, textured paint)
    double cross_max_m = 0.20;       // m; widest bar that may contain inner edges (one painted line)
    bool row_width_single = true;    // one image alone: slant widens a bar's blur allowance only, not its paint

    void bind(ParamMap &m) {
        m.add("min_edge_contrast", min_edge_contrast, 1.0, 255.0,
              "gray levels; smallest [-1 0 1] row response counted as a marking edge; 8 keeps faint "
              "markings in shadow and on concrete while sensor noise stays below it");
        m.add("noise_factor", noise_factor, 0.0, 20.0,
              "1; the edge threshold of a row is at least this times the row's mean absolute [-1 0 1] "
              "response, so road texture and JPEG noise give no edges while markings (several times the "
              "texture contrast) still do; 0 disables");
        m.add("min_bar_contrast", min_bar_contrast, 1.0, 255.0,
              "gray levels; a marking must be this much brighter than both of its sides; 10 as the edge "
              "threshold plus a margin for blur");
        m.add("min_bar_ratio", min_bar_ratio, 0.0, 2.0,
              "fraction; a marking must also be this much brighter relative to its brighter side, so the "
              "threshold scales with illumination (sunlit vs shadowed road, the thesis' fixed-threshold weakness)");
        m.add("marking_min_m", marking_min_m, 0.01, 1.0,
              "m; narrowest marking accepted; 0.08 below the 0.10-0.15 m of painted lines");
        m.add("marking_max_m", marking_max_m, 0.05, 2.0,
              "m; widest bright bar accepted as one marking; 0.45 covers 0.30 m edge lines and close double lines");
        m.add("max_range_m", max_range_m, 5.0, 500.0,
              "m; farthest range scanned; 60 m, beyond which a marking is one or two pixels wide");
        m.add("max_scan_rows", max_scan_rows, 8, 4096,
              "rows; at most this many rows are filtered (evenly spaced); bounds cost on large frames; 200 "
              "scans every row of small frames (Botts' dots are 2-4 rows tall) and every second row of a "
              "640x480 road area");
        m.add("min_run_rows", min_run_rows, 1, 2,
              "scanned rows; 2: a point is kept only if the next or previous scanned row has a point where the "
              "marking would continue (markings are long, texture specks and noise are not); 1 keeps all");
        m.add("work_width_px", work_width_px, 64, 8192,
              "px; frames at least twice this wide are averaged over blocks of width/work_width pixels before the "
              "marking filter (a 1280-wide marking then looks as at 640, at half the cost)");
        m.add("cross_inner_edges", cross_inner_edges,
              "a marking's bar may contain inner edges weaker than its own two edges if it stays brighter than both "
              "sides and is at most cross_max_m wide (worn paint on concrete; docs/lanes.md)");
        m.add("cross_max_m", cross_max_m, 0.01, 2.0,
              "m; with cross_inner_edges, the widest bar that may contain inner edges: one worn painted line, not a "
              "bright patch of concrete (docs/lanes.md)");
        m.add("row_width_single", row_width_single,
              "one image alone: a bar is at most 1.2 marking_max_m wide along its row plus 2 px of blur times the "
              "slant factor, not the whole bound times slant (docs/lanes.md)");
    }
};

// One marking centre found on one scanned row.
struct MarkingPoint {
    float x = 0.f, y = 0.f;
    float contrast = 0.f;  // gray levels above the brighter side
    float width = 0.f;     // px (full frame); the bar's width along the row
};

// The order of the marking points: by row, then column.
inline bool row_order(const MarkingPoint &a, const MarkingPoint &b) { return a.y < b.y || (a.y == b.y && a.x < b.x); }

constexpr float kMaxMarkingSlope = 6.f;  // |dx/dy| of the flattest marking considered (80 deg from vertical)

// The rows that are scanned: y_top..y_bottom inclusive, every `step` rows.
struct ScanBand {
    int y_top = 0, y_bottom = 0, step = 1;
    int rows() const { return y_bottom < y_top ? 0 : (y_bottom - y_top) / step + 1; }
};

// Band from max_range_m below the horizon prior down to the bottom (minus the bonnet).
ScanBand scan_band(cv::Size size, const CameraParams &cam, const HorizonPrior &hp,
                   const MarkingFilterParams &p);

// Marking centres on the rows of `band`; appends to `out` (cleared first). short_bars (cleared first, when
// given) receives the bars that pass the contrast tests but are no marking: narrower than marking_min_m allows,
// or alone on their row (min_run_rows); Botts' dots are such bars at low resolution (dot_markings.hpp).
// single_image: the frame is one image alone (not lane tracking): row_width_single applies.
void find_marking_points(const cv::Mat &gray, const ScanBand &band, const CameraParams &cam,
                         const HorizonPrior &hp, const MarkingFilterParams &p,
                         std::vector<MarkingPoint> &out, std::vector<MarkingPoint> *short_bars = nullptr,
                         bool single_image = false);

} // namespace hw
