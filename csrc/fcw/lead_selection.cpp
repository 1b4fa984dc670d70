#include "fcw/lead_selection.hpp"

#include <algorithm>
#include <cmath>

namespace hw {

namespace {

double overlap_share(double a0, double a1, double b0, double b1) {
    const double w = a1 - a0;
    return w > 0 ? std::max(0.0, std::min(a1, b1) - std::max(a0, b0)) / w : 0.0;
}

} // namespace

bool LeadSelector::lanes_believed(const LaneModel &lanes, double horizon_row) const {
    if (!lanes.certain || lanes.frames_since_observed > p_.lanes_stale_frames || !std::isfinite(horizon_row)) return false;
    const double y = std::max(lanes.ego_left.bottom.y, lanes.ego_right.bottom.y);  // lower end of the lines
    const double xl = lanes.ego_left.x_at(float(y)), xr = lanes.ego_right.x_at(float(y));
    if (!(y > horizon_row + 1.0) || !std::isfinite(xl) || !std::isfinite(xr)) return false;
    // flat road: Z = fy h / (y - y_h); the lane is (xr - xl) Z / fx metres wide there, and the car's centre
    // line images at u0 = cx - fx tan(yaw) - fx lateral / Z
    const double z = cam_.fy * cam_.height_m / (y - horizon_row);
    const double width_m = (xr - xl) * z / cam_.fx;
    const double u0 = cam_.cx - cam_.fx * std::tan(cam_.yaw_deg * M_PI / 180.0) - cam_.fx * cam_.lateral_m / z;
    return width_m >= p_.road.min_lane_width_m && width_m <= p_.road.max_lane_width_m && xl < u0 && u0 < xr;
}

int LeadSelector::update(std::vector<TrackState> &tracks, const LaneModel &lanes, const EgoMotion &ego,
                         double horizon_row) {
    const bool lanes_sure = lanes_believed(lanes, horizon_row);
    const double half_path = 0.5 * p_.ego_width_m + p_.path_margin_m;  // corridor half width without lanes
    double kappa = 0.0;  // path curvature, 1/m, left positive
    if (std::isfinite(ego.speed_mps) && std::isfinite(ego.yaw_rate_rps) && ego.speed_mps > 1.0)
        kappa = ego.yaw_rate_rps / ego.speed_mps;
    int best = -1;
    double best_range = p_.max_range_m;
    for (auto &t : tracks) {
        const double left = t.box.x, right = t.box.x + t.box.width, bottom = t.box.y + t.box.height;
        const double centre = 0.5 * (left + right);
        double share = NAN;
        const double xl = lanes.ego_left.x_at(float(bottom)), xr = lanes.ego_right.x_at(float(bottom));
        if (std::isfinite(horizon_row) && bottom < horizon_row + p_.horizon_margin_px) {
            share = 0.0;  // above the horizon: not standing on the road
        } else if (lanes_sure && std::isfinite(xl) && std::isfinite(xr) && xr > xl) {
            t.lane_index = int(std::floor((centre - xl) / (xr - xl)));
            share = overlap_share(left, right, xl, xr);
        } else if (std::isfinite(t.lateral_m) && std::isfinite(t.range_m)) {
            // the vehicle's extent across the road at its range (box width / fx * Z), against the corridor
            // around the predicted path x_p(Z) = -kappa Z^2 / 2
            const double half_w = 0.5 * t.box.width * t.range_m / cam_.fx;
            const double rel = t.lateral_m + 0.5 * kappa * t.range_m * t.range_m;
            t.lane_index = int(std::lround(rel / p_.road.lane_width_m));
            share = overlap_share(rel - half_w, rel + half_w, -half_path, half_path);
        }
        if (!std::isfinite(share)) continue;  // no lanes and no range: in_path stays unknown
        const bool is_lead = t.id >= 0 && t.id == lead_;
        t.in_path = share >= (is_lead ? p_.exit_overlap : p_.enter_overlap) ? 1 : 0;
        if (t.confirmed && t.in_path == 1 && std::isfinite(t.range_m) && t.range_m < best_range) {
            best_range = t.range_m;
            best = t.id;
        }
    }
    // The nearest in-path vehicle is the lead; the current one keeps its place by the lower exit share.
    lead_ = best;
    return lead_;
}

} // namespace hw
