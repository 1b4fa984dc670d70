// lead_selection.hpp - which lane each vehicle is in, whether it is in the ego path, and the lead.
//
// With a lane model, a vehicle's lane follows from where its bottom-centre falls between the ego
// boundaries at its contact row, and "in path" from how much of its width overlaps the ego lane.
// Without lanes, the ego path is predicted from yaw rate and speed (constant curvature
// kappa = yaw_rate / speed, lateral offset of the path at range Z: -kappa Z^2 / 2, left turns
// positive yaw rate) and a corridor of one lane width. Entering the path needs a clear overlap;
// the current lead keeps its place until it has left the lane, so a lead changing lanes is not
// dropped and re-acquired on every wobble.
#pragma once

#include "base/params.hpp"
#include "base/types.hpp"
#include "geometry/camera.hpp"

#include <vector>

namespace hw {

struct LeadParams {
    double lane_width_m = 3.6;     // lane width assumed where no lane model is available
    double enter_overlap = 0.35;   // share of a vehicle's width inside the ego lane to enter the path
    double exit_overlap = 0.05;    // the lead leaves the path below this share (it has left the lane)
    double max_range_m = 150.0;    // farther vehicles are never the lead

    void bind(ParamMap &m) {
        m.add("lane_width_m", lane_width_m, 2.0, 6.0,
              "m; lane width used for the ego corridor and lane index when no lane model is available");
        m.add("enter_overlap", enter_overlap, 0.0, 1.0,
              "share of the vehicle width inside the ego lane for it to be in path; 0.35 ignores an adjacent car "
              "touching the line but catches a cut-in early");
        m.add("exit_overlap", exit_overlap, 0.0, 1.0,
              "the current lead stays in path until its overlap falls below this: it has left the lane");
        m.add("max_range_m", max_range_m, 5.0, 500.0, "m; vehicles farther away are never the lead");
    }
};

class LeadSelector {
public:
    explicit LeadSelector(const LeadParams &p, const CameraParams &cam) : p_(p), cam_(cam) {}
    // Sets lane_index and in_path of every track; returns the lead id or -1.
    int update(std::vector<TrackState> &tracks, const LaneModel &lanes, const EgoMotion &ego);
    void reset() { lead_ = -1; }

private:
    LeadParams p_;
    CameraParams cam_;
    int lead_ = -1;
};

} // namespace hw
