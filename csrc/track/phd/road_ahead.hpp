// phd/road_ahead.hpp - whether a point of the image (a vehicle's bottom centre) stands on the road ahead: on the ego
// lane or at most `lanes_beside` lane widths beside it. The tracker starts vehicles only there, so the roadside's
// bushes, signs and barriers start no track.
//
// With a lane model that says (LaneModel::near_ego_lane), its ego boundaries widened by lanes_beside ego-lane widths
// each side. Without one (a road with no markings, lanes lost), the point on the flat road (camera model, the frame's
// horizon) against the ego path the yaw rate and speed predict (curvature kappa = yaw_rate / speed, lateral offset
// -kappa Z^2 / 2 at range Z; straight ahead when either is unknown): within (0.5 + lanes_beside) road.lane_width_m of
// it, the same width the lane model gives on a motorway. A point at or above the horizon is not on the road.
#pragma once

#include "base/types.hpp"
#include "geometry/camera.hpp"

namespace hw {

bool on_road_ahead(const LaneModel &lanes, const CameraParams &cam, const EgoMotion &ego, double horizon_row,
                   double lane_width_m, float u, float v, int lanes_beside);

} // namespace hw
