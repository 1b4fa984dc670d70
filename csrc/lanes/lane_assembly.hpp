// lane_assembly.hpp - marking lines -> lane model: vanishing point, ego and adjacent boundaries,
// road polygon.
//
// The thesis keeps the lines it found per half (left-most, left, right, right-most) and takes the
// polygon between the outer ones as the road. Here the lines are first checked against each other:
// the markings of a straight road meet in one vanishing point, so the point most lines pass through
// (within a window around the horizon the camera pitch predicts) is found by consensus and lines that
// miss it are dropped. Each remaining line's slope gives its lateral offset on a flat road
// (road_geometry.hpp), and the ego lane is the pair of lines either side of the camera whose spacing
// is a plausible lane width, which lets a spurious line inside the lane (tar seam, arrow, vehicle
// edge) lose against the real boundary. Adjacent boundaries are the lines one lane further out, and the
// outer ones the lines one lane beyond those (TuSimple labels up to two lanes each side).
#pragma once

#include "base/params.hpp"
#include "base/types.hpp"
#include "geometry/camera.hpp"
#include "geometry/road_params.hpp"
#include "lanes/road_geometry.hpp"

#include <vector>

namespace hw {

struct LaneAssemblyParams {
    RoadParams road;                     // section "road" (lane_width_m), handed in by the configuration
    double min_lane_width_frac = 0.6;    // of road.lane_width_m; narrowest plausible ego lane
    double max_lane_width_frac = 1.5;    // of road.lane_width_m; widest plausible ego lane
    double horizon_tolerance_deg = 4.0;  // deg; how far the true horizon may be from the pitch's
    double vp_inlier_frac = 0.02;        // fraction of width; a line passes through the VP within this
    double road_range_m = 80.0;          // m; top of the boundaries and of the road polygon
    double grid_tolerance = 0.3;         // lane widths; an adjacent boundary's offset from one lane out
    double hysteresis_m = 0.15;          // m; a boundary crossing under the camera changes side past this
    bool outer_lanes = false;            // report the boundaries two lanes out each side (where a line is there)

    void bind(ParamMap &m) {
        m.add("min_lane_width_frac", min_lane_width_frac, 0.1, 1.0,
              "fraction of road.lane_width_m; narrowest ego lane accepted; 0.6 allows narrow lanes and a camera "
              "height known only to +-30 %");
        m.add("max_lane_width_frac", max_lane_width_frac, 1.0, 3.0,
              "fraction of road.lane_width_m; widest ego lane accepted; 1.5, below the two lanes of a missed marking");
        m.add("horizon_tolerance_deg", horizon_tolerance_deg, 0.0, 30.0,
              "deg; how far the true horizon may lie from the one the camera pitch predicts (pitch known "
              "roughly, pitching on bumps); bounds where the vanishing point is searched");
        m.add("vp_inlier_frac", vp_inlier_frac, 0.001, 0.2,
              "fraction of the image width; a line passing this close to the vanishing point belongs to "
              "the road; 0.02 (13 px at 640) tolerates gentle curves");
        m.add("road_range_m", road_range_m, 10.0, 1000.0,
              "m; range where the lane boundaries and the road polygon end (a little below the "
              "vanishing point); 80 m covers the vehicles an FCW cares about");
        m.add("grid_tolerance", grid_tolerance, 0.05, 0.5,
              "lane widths; how far an adjacent boundary may lie from exactly one lane out");
        m.add("hysteresis_m", hysteresis_m, 0.0, 1.0,
              "m; during a lane change an ego boundary changes side (left <-> right) only once it is this "
              "far past the camera, so the model does not flicker while the car straddles it");
        m.add("outer_lanes", outer_lanes,
              "report the boundaries two lanes out each side too (ABI positions -3 and +3) where a measured or tracked "
              "line lies one lane beyond an adjacent boundary (within grid_tolerance); false: ego and adjacent only");
    }
};

// A line offered to the assembly, with how much it is trusted.
struct LaneCandidate {
    ImageLine line;
    float weight = 0.f;     // evidence: supporting rows, or track history
    bool observed = true;   // measured in this frame
    int id = -1;            // caller's identity (a track id), -1 for none
    LineFit fit;            // precision of a measured line (n = 0 when not a fit)
};

// Indices into the candidates (-1 = none) and the ego-lane width as a slope difference.
struct LaneAssignment {
    int ego_left = -1, ego_right = -1, adj_left = -1, adj_right = -1;
    int out_left = -1, out_right = -1;  // two lanes out (n = -2 and 3 lane widths from the ego left boundary)
    float width_k = kNaN;  // k_right - k_left of the ego lane (measured or expected)
};

// Consensus vanishing point of `lines` (weighted), searched within the prior's window; marks in
// `inlier` the lines passing through it. False (all lines inliers) when no two lines agree.
bool consensus_vanishing_point(const std::vector<LaneCandidate> &lines, const HorizonPrior &hp,
                               cv::Size size, const LaneAssemblyParams &p, cv::Point2f &vp,
                               std::vector<char> &inlier);

// Ego pair and adjacent boundaries among `c`. prev_left_id / prev_right_id: ids of last frame's ego
// boundaries (continuity; hysteresis when one crosses under the camera); expected_width_k: the
// ego width as a slope difference when known from tracking (NaN: from road.lane_width_m).
LaneAssignment assign_lanes(const std::vector<LaneCandidate> &c, const CameraParams &cam,
                            const LaneAssemblyParams &p, int prev_left_id = -1, int prev_right_id = -1,
                            float expected_width_k = kNaN);

// Fills boundaries, vanishing point (NaN if unknown), polygon and `valid` of `out` (other fields kept).
// Boundaries run from the bottom row up to road_range_m below the vanishing point (or horizon prior).
void build_lane_model(const std::vector<LaneCandidate> &c, const LaneAssignment &a, cv::Point2f vp,
                      cv::Size size, const CameraParams &cam, const HorizonPrior &hp,
                      const LaneAssemblyParams &p, LaneModel &out);

// Ego-lane width and the car's lateral offset in it (width_m, offset_m of `m`), from the ego boundaries
// at the bottom row: a column x there is X = (x - x_vp) / px_per_m metres right of the camera, the
// car's centre is -cam.lateral_m; offset = -lateral_m - (X_left + X_right) / 2. NaN unless both known.
void ego_lane_metrics(const CameraParams &cam, LaneModel &m);

// A convex quadrilateral clipped to the image; integer vertices.
std::vector<cv::Point> clip_to_image(const std::vector<cv::Point2f> &quad, cv::Size size);

// Road area between the outer boundaries of `m`: adjacent boundaries where known, else the ego lane
// widened by one lane each side; with no boundary, the camera-model default (ego lane +- 1.5 lanes
// up to road_range_m). Clipped to the image.
std::vector<cv::Point> road_polygon(const LaneModel &m, float width_k, cv::Size size,
                                    const CameraParams &cam, const HorizonPrior &hp,
                                    const LaneAssemblyParams &p);

} // namespace hw
