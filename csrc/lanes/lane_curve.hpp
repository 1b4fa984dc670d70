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
              "bend the lane boundaries to the road's curvature (x = a + b d + c / d below the horizon); "
              "true (default): measured on TuSimple's lane clips 0.848 / 0.250 / 0.264 (accuracy / FP / FN) against "
              "0.836 / 0.306 / 0.312 straight, on the 10-image sample 0.819 / 0.242 / 0.292 against 0.798 / 0.250 / "
              "0.300; on unmarked roads the lines found on vehicle sides bend too, but the lane evidence check "
              "(evidence_min) keeps such a model from the road prior and the lead (congestion_no_markings: the car "
              "ahead is the lead in all frames from 40 m, 0.81 without the check; headway eval --parts lanes); false "
              "keeps straight lines");
        m.add("curve_near_range_m", near_range_m, 5.0, 200.0,
              "m; the first pass of the curve fit takes the marking points nearer than this around the "
              "tracked straight lines; 25 m, where a 250 m radius bends a marking by a quarter lane");
        m.add("curve_corridor_lanes", corridor_lanes, 0.01, 0.5,
              "lane widths; a marking point belongs to a boundary within this distance of it (first pass: of "
              "the tracked line, then of the first fit); 0.12: of 0.04-0.12 the one that improves both TuSimple's "
              "lane clips and the lane sample over straight lines (0.06 is a little better on the clips, worse "
              "on the sample)");
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
              "points; each boundary also has an image second-order term e d^2 (lens distortion bends the "
              "markings near the image's bottom corners); a bend of 1 px at the bottom row costs as much as "
              "this many points' squared pixel error, so a few points cannot bend a boundary");
        m.add("curve_contrast_power", contrast_power, 0.0, 4.0,
              "1; each marking point weighs in the curve fit by min(1, its bar contrast / the median of the fitted "
              "points')^power: painted lines stand tens of gray levels above the road, the bright lip of a seam or the "
              "texture beside a marking, which the corridor also takes in, little more than the filter's threshold, "
              "and pulled the boundary off the paint on concrete; the cap keeps a vehicle's lamp or chrome inside the "
              "corridor from outweighing the paint; 0 weighs every point alike. 3: measured (headway eval "
              "--parts lanes) TuSimple's lane clips 0.864 / 0.208 / 0.208 (accuracy / FP / FN) and the 10-image "
              "sample 0.832 / 0.158 / 0.217, against 0.848 / 0.250 / 0.264 and 0.821 / 0.208 / 0.267 with 0; with "
              "cross_inner_edges 0.930 / 0.118 / 0.090 and 0.831 / 0.175 / 0.242 against 0.897 / 0.160 / 0.139 and "
              "0.815 / 0.225 / 0.275; the rendered scenarios' ego boundaries within 12 px (tests/test_lanes.py) in "
              "100 % of the frames of all four against 97-99 % with 0; 1, 2, 2.5, 3 and 4 tried, chosen on the clips "
              "and the sample");
        m.add("curve_single_shared_a", single_shared_a,
              "one image alone (the \"lanes\" stage, no tracking): the curve fit gives every boundary the same a, the "
              "column where the flat road's markings cross the horizon row (x_c + fx psi), as the road model says, instead "
              "of one a each; a line partly hidden by a vehicle (0313-1/33600's and 0313-2/520's left adjacent lines behind "
              "a pickup) was rotated by the vehicle's points inside its corridor and missed. Measured ("
              "headway eval --parts lanes): TuSimple's 10-image sample 0.829 / 0.100 / 0.183 (accuracy / FP / FN) against "
              "0.831 / 0.158 / 0.242 with one a each. Not in lane tracking: the clips read 0.906 / 0.118 / 0.118 with it "
              "there against 0.930 / 0.097 / 0.090 (0531/...793's tightening curve: one shared a with the constant-curvature "
              "c / d cannot follow it, and a wrong boundary pulls every other one with it)");
        m.add("curve_single_above_road", single_above_road, 0.0, 10.0,
              "1; one image alone (the \"lanes\" stage, single-image detection): the curve fit takes only the marking "
              "points at least this share brighter than the ego lane's road on their row (its median between the "
              "straight ego boundaries): paint and dots are retroreflective, well above the pavement (0313-1/14900's "
              "dots 190-230 against 134), while the road between a concrete seam and a shadow passes the marking "
              "filter, brighter than its dark sides, at the road's own gray (115-125 against 123) and pulled 14900's "
              "right ego line 15.9 px off its dots (3.2 px with this). TuSimple's 10-image sample 0.938 / 0 / 0.050 "
              "(accuracy / FP / FN) against 0.920 / 0.025 / 0.075 with 0 (every point); 0.05-0.15 read 0.936 / 0.025 / "
              "0.075, 0.2-0.35 0.938 / 0 / 0.050, 0.4 and 0.5 0.916 / 0.033 / 0.083 (0313-2/37400 loses a line); the "
              "clips' 240 frames each alone 0.853 / 0.261 / 0.272 against 0.849 / 0.261 / 0.275 at 512x288, 0.830 / "
              "0.267 / 0.315 against 0.825 / 0.289 / 0.337 at 1280x720. Not in lane tracking (not measured there: the "
              "clips keep 0.930 / 0.097 / 0.090); 0 disables (headway eval --parts lanes)");
        m.add("curve_far_range_m", far_range_m, 10.0, 10000.0,
              "m; the boundaries reported (ABI points, tracks file, TuSimple predictions) reach this range, "
              "the fitted curve extrapolated beyond the lane model's end (lanes.road_range_m, 80 m) when farther; 80 "
              "(no extrapolation): TuSimple's labels stop short of 100 m, and the extrapolated rows above their top count "
              "as wrong rows; measured (headway eval --parts lanes) lane sample 0.821 / 0.208 / 0.267 against "
              "0.819 / 0.242 / 0.292 with 100, clips unchanged (0.848 / 0.250 / 0.264); 50-90 tried, 50-80 identical "
              "(the model ends at 80 m), 90 one row better on the sample and one worse on the clips with "
              "cross_inner_edges");
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
