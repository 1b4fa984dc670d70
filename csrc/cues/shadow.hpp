// shadow.hpp - vehicle hypotheses from the shadow underneath (thesis 2.4.2.1).
//
// Scan the road area bottom-up for bright-to-dark vertical transitions (road below, shadow above),
// keep horizontal runs of such edge pixels at least min_run_px long, merge runs whose rows are
// within merge_rows, compare each merged edge with the vehicle width expected at its row, and
// reduce the edges over one vehicle to one bottom edge.
//
// Where the thesis used one fixed gradient threshold (and names that as its weakness), the
// thresholds here follow the road's own gray level, measured in every frame in cells of the road
// area (bands of rows x thirds across): an edge pixel needs a step of at least grad_rel times the
// local road level, and the pixel above it must be darker than dark_rel times that level (section
// shadow_edge, shared with the Kalman tracker's ROI search). A dark band
// much wider than a vehicle (an overpass or tree shadow across the road) is dropped here, also when
// lane markings break it into vehicle-sized pieces (its dark side goes on past their ends); an edge
// moderately wider than a vehicle (a long shadow at low sun) is kept for verification to find the
// vehicle's sides inside it. A shadow that a low sun casts past one side of its vehicle onto the road (lit
// road just above its dark band there, up to the next lane marking) is cut back to the vehicle's side.
#pragma once

#include "base/params.hpp"
#include "base/types.hpp"
#include "cues/road_prior.hpp"
#include "geometry/camera.hpp"

#include <vector>

namespace hw {

// What a shadow edge is on a road of a given gray level: section "shadow_edge", read by the shadow detector's scan
// and by the Kalman tracker's search for a tracked vehicle's bottom edge (track/kalman/roi_search.hpp), so that
// the tracker re-finds its vehicles by the edges the detector finds them by.
struct ShadowEdgeParams {
    double grad_rel = 0.12;         // minimal bright-to-dark step as a fraction of the road level
    double min_step_gray = 6.0;     // gray levels; floor of that step for very dark roads
    double dark_rel = 0.5;          // the shadow side must be darker than this fraction of the road level

    void bind(ParamMap &m) {
        m.add("grad_rel", grad_rel, 0.01, 1.0,
              "fraction of the local road gray level; smallest bright-to-dark step that is a shadow edge; "
              "adapts the thesis's fixed threshold to the illumination of each frame and region");
        m.add("min_step_gray", min_step_gray, 0.0, 100.0,
              "gray levels; floor of the step threshold on very dark roads (sensor noise)");
        m.add("dark_rel", dark_rel, 0.1, 1.0,
              "fraction of the local road gray level; the pixel above a shadow edge must be darker than this (a "
              "shadow is darker than the road, a marking's end is not; docs/detection.md)");
    }
};

struct ShadowParams {
    RoadPriorParams road;           // scan area and expected vehicle width (keys in this section)
    ShadowEdgeParams edge;          // section "shadow_edge", taken by share
    int min_run_px = 12;            // px; shortest shadow run kept (thesis: 10-15)
    double min_width_frac = 0.3;    // shortest merged edge as a fraction of the expected width
    double max_width_ratio = 3.0;   // merged edges wider than this many expected widths are dropped
    int merge_rows = 2;             // px; runs whose rows differ by at most this are merged (thesis: 2)
    int gap_px = 2;                 // px; gaps of at most this many non-edge pixels inside a run
    double join_gap_frac = 0.25;    // edges at one height with a gap below this many widths are joined
    int level_bands = 8;            // row bands for the road level
    int level_columns = 3;          // cells across the road per band
    double band_dark_frac = 0.5;    // dark share beside both ends that marks a piece of a band across the road
    double reduce_height_ratio = 0.8;  // edges up to this many widths above a lower edge belong to its vehicle
    double beside_rel = 0.25;       // lit road above a shadow's end (within this fraction of the road level): cut off
    double beside_rows_frac = 0.1;  // rows sampled above the shadow's dark band, in expected widths
    double beside_min_frac = 0.25;  // shortest stretch cut off an end, in expected widths
    double beside_rest_frac = 0.5;  // what remains of a cut edge, at least, in expected widths
    double beside_max_ratio = 1.5;  // edges wider than this many expected widths are left whole
    double beside_reach = 0.8;      // with one end cut, the edge reaches this many expected widths from it
    int max_hypotheses = 48;        // cap per frame (strongest kept), bounds the verification cost

    void share(const SectionLookup &c) {
        road.share(c);
        edge = c.get<ShadowEdgeParams>("shadow_edge");
    }
    void bind(ParamMap &m) {
        road.bind(m);
        m.add("min_run_px", min_run_px, 1, 200,
              "px; shortest run of shadow-edge pixels kept; the thesis keeps 10-15 px as the shortest "
              "bottom edge it can still verify");
        m.add("min_width_frac", min_width_frac, 0.0, 1.0,
              "fraction of the expected vehicle width; merged edges shorter than this are dropped; 0.3 "
              "keeps a vehicle whose shadow is partly hidden");
        m.add("max_width_ratio", max_width_ratio, 1.0, 20.0,
              "expected vehicle widths; merged edges wider than this are a shadow across the road "
              "(overpass, trees), not a vehicle; 3 still keeps a long low-sun shadow");
        m.add("merge_rows", merge_rows, 0, 20,
              "px; runs whose rows differ by at most this many pixels are one edge (thesis: 2)");
        m.add("gap_px", gap_px, 0, 20,
              "px; a run continues over this many non-edge pixels (noise, a thin wheel highlight)");
        m.add("join_gap_frac", join_gap_frac, 0.0, 1.0,
              "expected vehicle widths; edges at the same height separated by less than this are one "
              "shadow broken at the wheels; 0.25 stays below the gap between cars in adjacent lanes");
        m.add("level_bands", level_bands, 1, 64,
              "row bands in which the road gray level is measured; the level changes with range");
        m.add("level_columns", level_columns, 1, 16,
              "cells across the road per band; shaded and sunlit lanes get their own level");
        m.add("band_dark_frac", band_dark_frac, 0.0, 1.01,
              "share of dark pixels just above the edge over half a vehicle width beyond each end; when both reach "
              "it the edge is part of a shadow across the road; above 1 = off");
        m.add("reduce_height_ratio", reduce_height_ratio, 0.0, 3.0,
              "vehicle widths; an edge this far above a lower, overlapping edge is part of the same "
              "vehicle (bumper, window) and is dropped, leaving one bottom edge per vehicle");
        m.add("beside_rel", beside_rel, 0.0, 1.0,
              "fraction of the road gray level; a stretch at an edge's end with lit road just above its dark band "
              "is a low sun's shadow beside the vehicle and is cut off; 0 = off (docs/detection.md)");
        m.add("beside_rows_frac", beside_rows_frac, 0.01, 1.0,
              "expected vehicle widths; rows above a shadow column's dark band whose mean gray tells lit road "
              "from a vehicle's body (at least 2 rows)");
        m.add("beside_min_frac", beside_min_frac, 0.0, 1.0,
              "expected vehicle widths; shortest lit stretch cut off an edge's end (a few pixels of lit road are "
              "blur; docs/detection.md)");
        m.add("beside_rest_frac", beside_rest_frac, 0.0, 2.0,
              "expected vehicle widths; an edge is cut only when at least this much of it remains under the vehicle");
        m.add("beside_max_ratio", beside_max_ratio, 0.5, 10.0,
              "expected vehicle widths; an edge wider than this is left whole (more than one vehicle's shadow), for "
              "the verification to search inside it");
        m.add("beside_reach", beside_reach, 0.0, 2.0,
              "expected vehicle widths; with one end cut, the edge still reaches at least this far from it towards "
              "the sun (the shadow starts inside the vehicle's sunny side)");
        m.add("max_hypotheses", max_hypotheses, 1, 1000,
              "hypotheses per frame, strongest first; bounds the cost of verification");
    }
};

// One hypothesis: the bottom edge of a vehicle (shadow line), as a box whose bottom is the edge and
// whose height is the thesis's ROI side, half the edge length.
struct ShadowHypothesis {
    cv::Rect2f box;
    float strength = 0.f;            // mean bright-to-dark step of the edge / road level, 0..1
    float expected_width_px = kNaN;  // vehicle width expected at the bottom row
    float road_gray = kNaN;          // road gray level around the edge
};

// Adaptive thresholds for a road of gray level `road_gray`: a shadow-edge pixel has a 3x3 Sobel
// vertical response (bright below) of at least `grad` and a pixel above it of at most `dark`.
struct ShadowThresholds {
    int grad = 0;
    int dark = 0;
};
ShadowThresholds shadow_thresholds(float road_gray, const ShadowEdgeParams &p);

std::vector<ShadowHypothesis> shadow_hypotheses(const cv::Mat &gray, const LaneModel &lanes,
                                          const CameraParams &cam, const ShadowParams &p);

} // namespace hw
