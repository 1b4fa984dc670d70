// lane_evidence.hpp - is a boundary a painted marking? Its support along the road.
//
// On a road without paint the lane stage still finds "lines": the bright trim, plates and lights of
// vehicle rears, vehicle sides and barriers line up through the vanishing point well enough to pass the
// consensus, and a pair of them can have a plausible lane width. What such a line lacks is paint along
// the road: its marking points sit inside one vehicle's box (a few metres of range) or nowhere near the
// camera. A painted boundary, solid or dashed, has marking points spread over the range from the bonnet
// out to tens of metres. So the scanned range, from the band's near end out to `evidence_far_m`, is cut
// into `evidence_bins` bins of equal log range, and a boundary's support in a frame is the share of bins
// with at least one marking point on it that lies outside every confirmed vehicle's box (a vehicle hides
// the road: a bright bar there is the vehicle). Smoothed over frames (dash gaps, a vehicle passing over
// the line), the lane model is `certain` when both ego boundaries' support is at least `evidence_min`;
// the detector's road prior and the lead selection believe only a certain model (else they use the
// camera and the ego path from the yaw rate: docs/ARCHITECTURE.md, the lead without lanes).
#pragma once

#include "base/params.hpp"
#include "base/types.hpp"
#include "geometry/camera.hpp"
#include "lanes/marking_filter.hpp"

#include <opencv2/core.hpp>

#include <vector>

namespace hw {

struct LaneEvidenceParams {
    double tolerance_m = 0.25;  // m; a marking point supports a boundary this close to it (across the road)
    double min_tolerance_px = 2.0;  // px; never narrower (far rows)
    double max_width_m = 0.45;  // m; a bar wider than this (on the model's road) is no paint evidence; 0 disables
    double far_m = 25.0;        // m; support is counted from the band's near end out to this range
    int bins = 3;               // range bins, equal in log range
    double min_support = 0.5;   // smoothed share of bins with support for a boundary to be a marking
    double alpha = 0.2;         // smoothing gain per frame of a tracked boundary's support
    double min_outer_support = 0.67;  // share of bins; an outer boundary (two lanes out) needs this in its frame
    double solid_min_rows = 0.8;  // share of scanned rows; an ego boundary painted on this many is a solid edge line

    void bind(ParamMap &m) {
        m.add("evidence_tolerance_m", tolerance_m, 0.01, 2.0,
              "m across the road; a marking point supports a boundary this close to it; 0.25, half a marking "
              "width plus the straight line's error on a gentle curve");
        m.add("evidence_min_tolerance_px", min_tolerance_px, 0.5, 50.0,
              "px; the support tolerance is never narrower (far rows, marking-centre noise)");
        m.add("evidence_max_width_m", max_width_m, 0.0, 10.0,
              "m across the road; a marking point counts as paint on a boundary only if its bar is at most this "
              "wide, so gaps between dark vehicles are not paint; 0 disables (docs/lanes.md)");
        m.add("evidence_far_m", far_m, 5.0, 500.0,
              "m; a boundary's support is counted from the near end of the scanned band out to this range; "
              "40 m holds a few dashes of any dashed line");
        m.add("evidence_bins", bins, 1, 16,
              "count; the counted range is cut into this many bins of equal log range; a boundary's support is "
              "the share of bins holding a marking point on it outside the confirmed vehicles' boxes; 3: a "
              "vehicle rear or side spans one");
        m.add("evidence_min", min_support, 0.0, 1.0,
              "share of bins; a boundary whose smoothed support is below this is not believed painted; without two "
              "believed ego boundaries the road prior and lead selection ignore the lanes; 0 = believe all");
        m.add("evidence_alpha", alpha, 0.01, 1.0,
              "1; smoothing gain per frame of a tracked boundary's support (dash gaps, a vehicle passing over "
              "the line); 0.2 takes about 5 frames to believe a new boundary");
        m.add("evidence_min_outer", min_outer_support, 0.0, 1.0,
              "share of bins; a boundary two lanes out (lanes.outer_lanes) is reported only with paint in at least "
              "this share of the range bins in its frame; 0.67 (two of three bins)");
        m.add("solid_edge_min_rows", solid_min_rows, 0.0, 1.0,
              "share of the scanned rows out to evidence_far_m; an ego boundary painted on at least this share is "
              "the carriageway's solid edge: nothing beyond it is reported (docs/lanes.md)");
    }
};

// Share (0..1) of the range bins in which `b` (its curve) has a marking point of `pts` within the
// tolerance that lies outside every box of `hidden`. y_h: horizon row; y_near: the scanned band's
// bottom row; visible_only: of the bins where `b` is inside the image (else of all). 0 when the
// boundary is not valid.
float boundary_support(const LaneBoundary &b, const std::vector<MarkingPoint> &pts,
                       const std::vector<cv::Rect2f> &hidden, float y_h, float y_near, const CameraParams &cam,
                       const LaneEvidenceParams &p, bool visible_only = false);

// Share (0..1) of the scanned rows of `band` out to far_m where `b` is in the image on which `b` has a marking
// point of `pts` within the tolerance outside every box of `hidden`: near 1 for a solid line, a quarter to a
// half for a dashed one. 0 when the boundary is not valid.
float boundary_row_coverage(const LaneBoundary &b, const std::vector<MarkingPoint> &pts,
                            const std::vector<cv::Rect2f> &hidden, float y_h, const ScanBand &band,
                            const CameraParams &cam, const LaneEvidenceParams &p);

// The outer boundaries (two lanes out) of `m` whose support in this frame is below p.min_outer_support
// are dropped: far out, a line one lane beyond the adjacent boundary is as often a shoulder, a barrier's
// foot or a seam as the next marking, and only paint along the road tells them apart.
void drop_unsupported_outer(LaneModel &m, const std::vector<MarkingPoint> &pts, const std::vector<cv::Rect2f> &hidden,
                            float y_h, float y_near, const CameraParams &cam, const LaneEvidenceParams &p);

// The carriageway ends at a solid ego boundary (solid_min_rows; 0 disables): the adjacent and outer boundaries
// beyond an ego boundary painted on at least that share of the scanned rows are dropped (a shoulder's or
// pavement's edge, a barrier's foot: TuSimple labels none of them).
void drop_beyond_solid_edges(LaneModel &m, const std::vector<MarkingPoint> &pts, const std::vector<cv::Rect2f> &hidden,
                             float y_h, const ScanBand &band, const CameraParams &cam, const LaneEvidenceParams &p);

} // namespace hw
