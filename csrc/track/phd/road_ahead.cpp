#include "track/phd/road_ahead.hpp"

#include "geometry/flat_road.hpp"

#include <cmath>

namespace hw {

bool on_road_ahead(const LaneModel &lanes, const CameraParams &cam, const EgoMotion &ego, double horizon_row,
                   double lane_width_m, float u, float v, int lanes_beside) {
    const float l = lanes.ego_left.x_at(v), r = lanes.ego_right.x_at(v);
    if (lanes.valid && std::isfinite(l) && std::isfinite(r) && r > l) return lanes.near_ego_lane(u, v, lanes_beside);
    const RoadPoint p = road_point(cam, u, v, horizon_row);
    if (!p.valid()) return false;
    double kappa = 0.0;  // 1/m, left positive
    if (std::isfinite(ego.speed_mps) && std::isfinite(ego.yaw_rate_rps) && ego.speed_mps > 1.0)
        kappa = ego.yaw_rate_rps / ego.speed_mps;
    const double path_x = -0.5 * kappa * p.z_m * p.z_m;
    return std::abs(p.x_m - path_x) <= (0.5 + lanes_beside) * lane_width_m;
}

} // namespace hw
