// lane_curve.hpp - the tracked straight boundaries bent to the road's curvature (flat-road model).
//
// A marking at lateral offset X0 on a road of curvature C (1/m) and heading psi relative to the
// camera lies at X(Z) = X0 + psi Z + C Z^2 / 2. With x = x_c + fx X / Z and Z = fy h / d, d = y - y_h
// (rows below the horizon), its image is
//     x(d) = a + b d + c / d,   a = x_c + fx psi,  b = fx X0 / (fy h),  c = fx fy h C / 2
// (road_geometry.hpp's straight line is c = 0). Every boundary of one road shares a and c; b is its
// own lateral offset. Near the car (large d) c / d vanishes and the boundaries are the straight
// lines the Hough stage and the tracker find; far away c / d bends them.
// The joint least-squares fit over the marking points near all boundaries gives c (a dashed marking
// takes its bend from a solid one) and, over frames, one a per boundary (a curve that tightens is not
// one c / d, and a wrong boundary would pull the shared a of all); one image alone shares a as the model
// says (curve_single_shared_a: a boundary with few points of its own is not rotated by a vehicle's); c is smoothed over frames (a pseudo-measurement of last
// frame's value), bounded by the tightest curve radius. Points are taken in two passes: near rows
// around the tracked lines first, then every scanned row around the first fit, so the bend does not
// pull in points of another marking. Each point weighs by min(1, its bar contrast / the fitted points'
// median)^3: the corridor also takes in the bright lip of a concrete seam or texture beside the paint,
// and the paint, tens of gray levels brighter, must win (a brighter vehicle lamp weighs no more than paint). Boundaries without enough points of
// their own are bent by the shared c around their tracked line (unchanged at the bottom row, slope included).
#pragma once

#include "base/params.hpp"
#include "base/types.hpp"
#include "geometry/camera.hpp"
#include "lanes/marking_filter.hpp"

#include <vector>

namespace hw {

struct LaneCurveParams {
    // Off by default: alone, on the synthetic congestion scenario without markings (lines found on vehicle sides)
    // the bent boundaries cut the tracked share of the car ahead from 0.92 to 0.81; with lanes.reject_in_vehicles
    // it is 0.91, but that pair costs the same scenario precision (0.976 -> 0.861) and, with the one hood line of
    // every stage, the real clips' FP (0.326 against 0.306 straight) (headway eval --parts lanes).
    bool enabled = true;               // bend the boundaries (false: straight lines)
    double near_range_m = 25.0;        // m; first pass uses rows nearer than this (curve small there)
    double corridor_lanes = 0.12;      // lane widths; a point farther than this from a boundary is not its
    double min_corridor_px = 3.0;      // px; corridor never narrower (far rows, marking noise)
    int min_points = 12;               // points; fewest on a boundary for it to enter the fit
    double min_radius_m = 150.0;       // m; tightest curve represented (bounds c)
    double prior_points = 40.0;        // points; weight of last frame's c in this frame's fit
    double residual_sigma_px = 2.0;    // px; residuals beyond 3 sigma are dropped in the refit
    double prior_e_points = 20.0;      // points; weight keeping the image second-order term at 0
    double contrast_power = 3.0;       // 1; points weigh by min(1, contrast / median)^power (0: alike)
    bool single_shared_a = true;       // one image alone: every boundary crosses the horizon row at one column
    double far_range_m = 80.0;         // m; the reported boundaries reach this range (extrapolated beyond road_range_m)
    double single_above_road = 0.25;   // 1; one image alone: fitted points this share brighter than the ego lane's road

    void bind(ParamMap &m) {
        m.add("curve_enabled", enabled,
              "bend the lane boundaries to the road's curvature (x = a + b d + c / d below the horizon); false = "
              "straight boundaries (docs/lanes.md)");
        m.add("curve_near_range_m", near_range_m, 5.0, 200.0,
              "m; the first pass of the curve fit takes the marking points nearer than this around the "
              "tracked straight lines; 25 m, where a 250 m radius bends a marking by a quarter lane");
        m.add("curve_corridor_lanes", corridor_lanes, 0.01, 0.5,
              "lane widths; a marking point belongs to a boundary within this distance of it (first pass: of the "
              "tracked line, then of the first fit)");
        m.add("curve_min_corridor_px", min_corridor_px, 0.5, 50.0,
              "px; narrowest corridor (far rows, where a lane is a few px wide)");
        m.add("curve_min_points", min_points, 3, 1000,
              "points; a boundary takes part in the curve fit with at least this many points");
        m.add("curve_min_radius_m", min_radius_m, 10.0, 100000.0,
              "m; tightest curve radius represented; 150 m bounds highway and main-road bends and keeps a "
              "bad fit from folding a boundary across the image");
        m.add("curve_prior_points", prior_points, 0.0, 10000.0,
              "points; weight of last frame's curvature in this frame's fit (smoothing over frames: a "
              "frame with few far points hardly moves it); 0 fits each frame alone");
        m.add("curve_residual_sigma_px", residual_sigma_px, 0.1, 50.0,
              "px; noise of a marking point about the curve; the refit drops points beyond 3 sigma");
        m.add("curve_prior_e_points", prior_e_points, 0.0, 1e6,
              "points; weight of the prior against each boundary's second-order image term e d^2 (lens distortion): "
              "a 1 px bend at the bottom row costs as much as this many points' squared error");
        m.add("curve_contrast_power", contrast_power, 0.0, 4.0,
              "1; each marking point weighs in the curve fit by min(1, its contrast / the fitted points' "
              "median)^power, so paint outweighs seams and texture; 0 = every point alike (docs/lanes.md)");
        m.add("curve_single_shared_a", single_shared_a,
              "one image alone: every boundary shares the column where the road's markings cross the horizon, as "
              "the flat road model says, so a half-hidden line is not rotated by a vehicle (docs/lanes.md)");
        m.add("curve_single_above_road", single_above_road, 0.0, 10.0,
              "1; one image alone: the curve fit takes only marking points at least this share brighter than the "
              "ego lane's road on their row (paint, not seams); 0 = every point (docs/lanes.md)");
        m.add("curve_far_range_m", far_range_m, 10.0, 10000.0,
              "m; the reported boundaries (ABI points, tracks file, TuSimple predictions) reach this range, the "
              "curve extrapolated beyond the lane model's end when farther (docs/lanes.md)");
    }
};

// Curvature state carried over frames by the tracker.
struct LaneCurveState {
    float c = 0.f;        // px^2; shared curvature term of the last frame (x = a + b d + c / d)
    bool known = false;   // a fit has been made
};

// Bends the valid boundaries of `m` (straight lines from bottom to top) to the road's curvature,
// measured on `pts`, with the horizon at row y_h. Writes curve / curve_row of each boundary and the
// boundaries' top points (now on the curve). Updates `state`. shared_a: every fitted boundary has the same a
// (the flat road's x_c + fx psi, where all markings of one road cross the horizon row); false: one a each.
void fit_lane_curves(const std::vector<MarkingPoint> &pts, float y_h, const CameraParams &cam, float lane_width_m,
                     const LaneCurveParams &p, LaneCurveState &state, LaneModel &m, bool shared_a = false);

// Row of the far end of the reported boundaries: far_range_m on a horizon at y_h (NaN if unknown).
float far_row(const CameraParams &cam, float y_h, const LaneCurveParams &p);

// n >= 2 points of boundary b from its bottom point up to row y_far (beyond its top point: the curve
// extrapolated; its top point when y_far is NaN, below the top or the boundary has no horizon row),
// rows evenly spaced in log(y - curve_row), i.e. in log range, so a polyline through them follows the
// c / d bend to a fraction of a pixel; evenly in y when the boundary has no horizon row.
void sample_boundary(const LaneBoundary &b, float y_far, int n, float *xs, float *ys);

} // namespace hw
