// lead_selection.hpp - which lane each vehicle is in, whether it is in the ego path, and the lead.
//
// With a lane model, a vehicle's lane follows from where its bottom-centre falls between the ego
// boundaries at its contact row, and "in path" from how much of its width overlaps the ego lane.
// Without lanes, or while the lane model has not been measured for a while (uncertain), the ego path
// or the lane model is implausible (its ego lane narrower or wider than a lane on the flat road, or
// not containing the car's own centre line: lines found on vehicles or seams of an unmarked road)
// is predicted from the yaw rate (CAN, else the road plane's image motion) and speed (constant
// curvature kappa = yaw_rate / speed, lateral offset of the path at range Z: -kappa Z^2 / 2, left turns
// positive yaw rate), as a corridor as wide as the ego vehicle plus a margin each side; a vehicle
// is in it when its width at its contact row overlaps the corridor. Entering the path needs a clear overlap;
// the current lead keeps its place until it has left the lane, so a lead changing lanes is not
// dropped and re-acquired on every wobble. A box whose bottom is not below the horizon (it does not
// stand on the road) is never in path, lanes or not.
#pragma once

#include "base/params.hpp"
#include "base/types.hpp"
#include "geometry/camera.hpp"
#include "geometry/road_params.hpp"

#include <vector>

namespace hw {

struct LeadParams {
    RoadParams road;               // section "road": lane width without lanes, believable lane widths
    double enter_overlap = 0.35;   // share of a vehicle's width inside the ego lane to enter the path
    double exit_overlap = 0.05;    // the lead leaves the path below this share (it has left the lane)
    double max_range_m = 150.0;    // farther vehicles are never the lead
    double ego_width_m = 1.8;      // ego vehicle width: the path corridor without lanes
    double path_margin_m = 0.2;    // added each side of the ego width
    int lanes_stale_frames = 15;   // lanes not measured for this many frames are uncertain: use the path
    double horizon_margin_px = 2.0; // a box bottom less than this below the horizon is not on the road

    void bind(ParamMap &m) {
        m.add("enter_overlap", enter_overlap, 0.0, 1.0,
              "share of the vehicle width inside the ego lane for it to be in path; 0.35 ignores an adjacent car "
              "touching the line but catches a cut-in early");
        m.add("exit_overlap", exit_overlap, 0.0, 1.0,
              "the current lead stays in path until its overlap falls below this: it has left the lane");
        m.add("max_range_m", max_range_m, 5.0, 500.0, "m; vehicles farther away are never the lead");
        m.add("ego_width_m", ego_width_m, 1.0, 3.5,
              "m; ego vehicle width; without a lane model the ego path is a corridor this wide (plus path_margin_m "
              "each side) along the curvature the yaw rate gives");
        m.add("path_margin_m", path_margin_m, 0.0, 1.5,
              "m; margin each side of the ego width; 0.2 keeps a car in the adjacent lane (centre 3.6 m off) out "
              "and a lead offset by half a metre in");
        m.add("lanes_stale_frames", lanes_stale_frames, 0, 100000,
              "frames; a lane model carried over without a measurement for longer than this (0.5 s at 30 fps) is "
              "uncertain and the path from the yaw rate is used instead");
        m.add("horizon_margin_px", horizon_margin_px, 0.0, 100.0,
              "px; a box whose bottom is not at least this far below the horizon row does not stand on the road "
              "and is never the lead");
    }
};

class LeadSelector {
public:
    explicit LeadSelector(const LeadParams &p, const CameraParams &cam) : p_(p), cam_(cam) {}
    // Sets lane_index and in_path of every track; returns the lead id or -1. `horizon_row`: this frame's.
    int update(std::vector<TrackState> &tracks, const LaneModel &lanes, const EgoMotion &ego, double horizon_row);
    void reset() { lead_ = -1; }
    void set_camera(const CameraParams &cam) { cam_ = cam; }  // self-calibration's estimate

private:
    LeadParams p_;
    CameraParams cam_;
    // The lane model is measured recently and geometrically plausible.
    bool lanes_believed(const LaneModel &lanes, double horizon_row) const;
    int lead_ = -1;
};

} // namespace hw
