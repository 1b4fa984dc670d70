// hough_lines.hpp - marking points -> one straight line per lane marking (thesis: Hough per half).
//
// As in the thesis the image is split into a left and a right half and a Hough transform finds the
// lines of each; the many lines found on one marking are grouped by angle and reduced to one, and
// lines with implausible angles are rejected. Differences, each for a reason:
//  - the accumulator is centred on a vanishing point, so rho is a line's distance from it. A wide
//    window (|rho| up to max_vp_offset_frac of the width, coarse bins) around the camera's expected
//    vanishing point finds the strong lines, whose consensus gives the measured vanishing point
//    (lane_assembly); a narrow window (vp_line_tol_frac) around that point (or the tracked one) then
//    finds every marking, dashed and dotted ones too: every marking of a straight road passes through
//    the vanishing point, while vehicle edges and road-side structure rarely do (rejection by
//    position, not only by angle). A point only votes in the few angle bins whose line can pass that
//    close, so the narrow search is cheap;
//  - the halves split at the vanishing-point column and overlap, and each half also accepts lines
//    that lean slightly the other way, so a marking passing under the camera during a lane change is
//    still found (the thesis' halves lose it);
//  - each Hough peak, strongest first, is refined by a least-squares fit to the points near it
//    (sub-bin accuracy; a tracked vanishing point counts as a few extra points, so a line seen on one
//    short dash takes its direction from it), and claims those points: a weaker peak sharing them
//    (a dash plus a tail light) is judged on what is left. Lines with too little support, or support
//    bunched in a few rows (one vehicle), are rejected.
#pragma once

#include "base/params.hpp"
#include "geometry/camera.hpp"
#include "lanes/marking_filter.hpp"
#include "lanes/road_geometry.hpp"

#include <vector>

namespace hw {

struct HoughLinesParams {
    double theta_step_deg = 1.0;      // deg; accumulator angle bin
    double rho_step_px = 2.0;         // px; accumulator distance bin
    double max_angle_deg = 80.0;      // deg from vertical; flatter lines are rejected
    double cross_angle_deg = 10.0;    // deg; a half also accepts lines leaning this much the other way
    double max_vp_offset_frac = 0.2;  // fraction of width; farthest a line may pass from the expected VP
    double vp_line_tol_frac = 0.03;   // fraction of width; same, once the VP is measured
    int min_votes = 6;                // scanned rows; fewest supporting rows of a line
    double min_votes_frac = 0.05;     // fraction of scanned rows; same, relative to the band
    double inlier_frac = 0.006;       // fraction of width; distance of a supporting point from its line
    double min_span_frac = 0.12;      // fraction of the band height the support must span
    double group_angle_deg = 3.0;     // deg; lines closer in angle may be one marking (thesis grouping)
    double group_sep_m = 0.5;         // m; lines closer laterally than this are one marking
    double vp_anchor_points = 8.0;    // points; pull of a tracked vanishing point on each line fit
    int max_peaks_per_half = 12;      // Hough peaks examined per half

    void bind(ParamMap &m) {
        m.add("theta_step_deg", theta_step_deg, 0.1, 10.0,
              "deg; Hough angle bin; 1 deg, finer than the grouping tolerance, the fit refines it");
        m.add("rho_step_px", rho_step_px, 0.5, 20.0, "px; Hough distance bin; 2 px, the fit refines it");
        m.add("max_angle_deg", max_angle_deg, 10.0, 89.0,
              "deg from vertical; lines flatter than this are not markings (thesis: reject by angle); 80 "
              "keeps the outer line of an adjacent lane");
        m.add("cross_angle_deg", cross_angle_deg, 0.0, 45.0,
              "deg; each half also accepts lines leaning this far the other way, so a marking under the "
              "camera (lane change) is found");
        m.add("max_vp_offset_frac", max_vp_offset_frac, 0.01, 2.0,
              "fraction of the image width (plus the horizon tolerance); farthest a line may pass from "
              "the expected vanishing point; 0.2 allows curves and a poorly known yaw");
        m.add("vp_line_tol_frac", vp_line_tol_frac, 0.001, 0.5,
              "fraction of the image width; once the vanishing point is measured, the lines are searched again "
              "passing this close to it (gentle curves in, vehicle edges out)");
        m.add("min_votes", min_votes, 2, 10000, "scanned rows; fewest rows supporting a line");
        m.add("min_votes_frac", min_votes_frac, 0.0, 1.0,
              "fraction of the scanned rows; fewest supporting rows relative to the band; 0.05 keeps "
              "dashed lines (about a quarter of the near rows painted)");
        m.add("inlier_frac", inlier_frac, 0.0005, 0.1,
              "fraction of the image width; farthest a supporting point lies from its line (3.8 px at 640)");
        m.add("min_span_frac", min_span_frac, 0.0, 1.0,
              "fraction of the scanned band height; the middle 80 % of a line's support must span at least this "
              "much (a marking runs the whole band, one vehicle's edges do not)");
        m.add("group_angle_deg", group_angle_deg, 0.1, 30.0,
              "deg; lines closer in angle than this may belong to one marking (thesis grouping)");
        m.add("group_sep_m", group_sep_m, 0.05, 3.0,
              "m; lines closer laterally than this are one marking (both edges, double lines); well "
              "below a lane width");
        m.add("vp_anchor_points", vp_anchor_points, 0.0, 1000.0,
              "points; around a tracked vanishing point each line fit counts the vanishing point as this many extra "
              "points (a short dash takes its direction from it); 0 = the points alone");
        m.add("max_peaks_per_half", max_peaks_per_half, 1, 64,
              "count; Hough peaks examined in each half (thesis: two per half; more for adjacent lanes)");
    }
};

// One line per marking.
struct LaneLine {
    ImageLine line;         // x(y) fitted to the supporting points; y_ref = bottom scanned row
    float votes = 0.f;      // scanned rows supporting the line
    float y_min = 0.f, y_max = 0.f;  // rows spanned by the support
    float span = 0.f;       // rows between the 10th and 90th percentile of the support
    LineFit fit;            // precision of the fitted line (anchor included)
};

// Where the transform looks: lines passing within rho_max of `origin`, at this resolution.
struct HoughWindow {
    cv::Point2f origin;
    float rho_max = 0.f;          // px
    float theta_step_deg = 1.f;   // deg
    float rho_step_px = 2.f;      // px
    int max_peaks = 8;            // per half
    float anchor_weight = 0.f;    // points' worth of pull of the line fits towards `origin`
};

// Wide window around the prior vanishing point (coarse bins): finds the strong lines whose
// consensus gives the vanishing point.
HoughWindow wide_window(cv::Size size, const HorizonPrior &hp, const HoughLinesParams &p);
// Narrow window around a measured vanishing point (fine bins): finds every marking of the road,
// faint and dashed ones too, without the clutter lines that do not pass through it. Only a tracked
// vanishing point (smoothed over frames) anchors the line fits; one measured in this frame alone is
// a compromise of lines that may not quite meet (curves) and would bend them.
HoughWindow vp_window(cv::Point2f vp, bool tracked, cv::Size size, const HoughLinesParams &p);

// Lines of the lane markings among `pts`, one per marking, sorted left to right at the bottom row.
std::vector<LaneLine> hough_lane_lines(const std::vector<MarkingPoint> &pts, const ScanBand &band,
                                       cv::Size size, const CameraParams &cam, const HorizonPrior &hp,
                                       const HoughLinesParams &p, const HoughWindow &win);

} // namespace hw
