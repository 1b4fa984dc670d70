// parallax/aligned_difference.hpp - moving vehicles from the difference of two road-aligned frames (paper 000,
// section II-C).
//
// The previous frame is warped with the road homography H (previous -> current), so every road
// pixel lands where it is now; the absolute difference |I_k - warp(I_{k-1}, H)| is then near zero on
// the road and large where something is not on the road plane or moves on it: the vehicles (their
// contact zone, bumper, window edges) and structures standing above the road. The difference is
// summed over cells (SAD), cells above max(sad_min, sad_factor x the median road cell, edge_slack_px x
// the cell's mean gradient) are hot (the last term discounts what any warp leaves at strong edges:
// interpolation blur and the last tenths of a pixel of alignment error, on markings above all), and
// the image is scanned bottom-up: the lowest hot cluster that sits on the road area starts a
// region, and the hot clusters above it within the height a vehicle of that width can have join it.
// Each region gives one measurement at its mid-lower point, whose row is refined on the current
// frame to the strongest dark-above / bright-below step near the region's bottom (the shadow under
// the vehicle; for a vehicle standing still relative to the road the contact zone itself shows no
// parallax and the lowest difference lies higher up). The box's top comes from the region's hot rows,
// or, when the vehicle's sides reach higher as vertical edges in the current frame, from those
// (vehicle_top.hpp): a truck's flat back shows no difference and its roof stands above the road band.
//
// Structures above the road plane are rejected by measurement, not by masks: clusters are formed on
// the road area of the lane model only, most of a region's lowest cells must lie inside it by
// inside_margin_m, its bottom must be below the horizon, its width must be that of a vehicle at that
// row (the flat-road scale), and a region that is a long thin streak pointing at the vanishing point
// (a guardrail or kerb running along the road, where the lane model extrapolated a lane over the
// verge) is no vehicle; what remains is left to the temporal coherence the particle filter demands.
//
// The difference is taken at pyramid level `level` (1 = half resolution) of the road band: a
// quarter of the pixels to warp, and a low-pass that removes most of the sensor noise.
#pragma once

#include "base/params.hpp"
#include "base/types.hpp"
#include "detect/photometric.hpp"
#include "geometry/camera.hpp"
#include "geometry/vehicle_shape.hpp"

#include <opencv2/core.hpp>

#include <vector>

namespace hw {

struct ParallaxParams {
    int level = 1;                   // pyramid level the difference is taken at (0 = full resolution)
    int cell_w_px = 8;               // px (full resolution); SAD cell width
    int cell_h_px = 4;               // px; SAD cell height
    double sad_min = 5.0;            // gray levels; mean |difference| of a hot cell, floor
    double sad_factor = 3.0;         // hot above this many times the median road cell
    double edge_slack_px = 0.5;      // px at the level; hot only beyond this displacement of the local gradient
    bool photometric = true;         // take the smooth brightness change out of the difference
    double photometric_trim = 3.0;   // robust sigmas; road cells farther from the brightness surface are left out
    // section "vehicle_shape" (the width the scan expects, the tallest box, the lowest top trusted, the top search's
    // height), taken by the parallax section's share
    VehicleShapeParams shape;
    double min_width_frac = 0.3;     // region narrower than this share of the expected width: no vehicle
    double max_width_frac = 2.2;     // wider: no single vehicle
    double inside_margin_m = 0.5;    // m; most of a region's bottom cells lie this far inside the road area
    double bottom_band_frac = 0.25;  // rows over which a region's width is measured, in expected widths
    double side_frac = 0.6;          // side columns reach this share of the band's strong columns
    double body_min_frac = 0.6;      // the body gives the sides when it spans this share of the band
    // box height / width reported at least: the floor of this detector's box for a region whose upper edges showed
    // no parallax, not a vehicle's shape (vehicle_shape), so the key stays here
    double min_aspect = 0.6;
    double height_hot_frac = 0.25;   // share of the columns hot for a row to count towards the height
    double height_gap_frac = 0.15;   // widths of rows without difference bridged for the height
    bool find_top = true;            // top from the current frame's side edges (vehicle_top.hpp) when higher than
                                     // vehicle_shape.top_min_aspect widths (cars keep the region's height)
    double top_keep_frac = 0.35;     // side edge strength, relative to the lower body, that still counts
    int top_max_gap = 2;             // px; gaps in the side edges bridged going up
    double top_snap_frac = 0.1;      // widths; sides moved to the strongest vertical edge within this first
    int join_gap_cells = 2;          // cells; hot clusters this far beside a region's span still join it
    double streak_elongation = 5.0;  // elongation of a region's cells beyond which ...
    double streak_angle_deg = 12.0;  // ... a long axis this close to the vanishing point's direction is no vehicle
    double refine_up_frac = 0.15;    // bottom search above the lowest hot row, in expected widths
    double refine_down_frac = 0.5;   // and below it (vehicles standing still on the road)
    double refine_min_step = 8.0;    // gray levels; weakest dark-to-bright step accepted as the bottom
    double horizon_margin_px = 4.0;  // px; a region's bottom must be this far below the horizon
    double bottom_margin_px = 4.0;   // px; a region reaching this close to the road area's bottom is cut by it

    void bind(ParamMap &m);
};

// One region of differences.
struct ParallaxMeasurement {
    cv::Point2f point;   // mid-lower point: bottom-centre of the region, px
    cv::Rect2f box;      // vehicle box: the region's columns, its bottom, a height from the region (clamped) or,
                         // higher, from its side edges in the current frame (find_top)
    float sad = 0.f;     // mean |difference| of its hot cells, gray levels
    bool refined = false;  // bottom row moved to a shadow step on the current frame
};

// Per-frame diagnostics.
struct ParallaxFrame {
    std::vector<ParallaxMeasurement> measurements;
    float road_residual = kNaN;   // gray levels; mean |difference| over road cells that are not hot
    float threshold = kNaN;       // gray levels; the hot-cell threshold used
    int hot_cells = 0;
    BrightnessSurface brightness; // the brightness change taken out (level coordinates of the band)
    cv::Mat hot;                  // CV_8UC1 cell map (255 hot); cell (r, c) covers full-resolution pixels
    cv::Size2f cell;              //   x in [c, c+1) * cell.width, y in band_top + [r, r+1) * cell.height
};

// cur_band / prev_band: the road band (rows band_top .. height-1) of the current and previous frame at
// pyramid level p.level; cur_full: the whole current frame (bottom refinement); H: road homography
// previous -> current in full-resolution pixels; lanes: this frame's lane model (road area,
// vanishing point); vp: the road's vanishing point in the current frame (its row is the horizon).
// grad_cells: optional cache of the current band's mean gradient per cell (CV_32F, cells x cells): filled
// when empty or of another size, used as it is otherwise (a second difference on the same band).
ParallaxFrame detect_parallax(const cv::Mat &cur_band, const cv::Mat &prev_band, const cv::Mat &cur_full, int band_top,
                              const cv::Matx33d &H, const LaneModel &lanes, cv::Point2f vp, const CameraParams &cam,
                              const ParallaxParams &p, cv::Mat *grad_cells = nullptr);

} // namespace hw
