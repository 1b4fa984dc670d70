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

int LeadSelector::update(std::vector<TrackState> &tracks, const LaneModel &lanes, const EgoMotion &ego) {
    int best = -1;
    double best_range = p_.max_range_m;
    for (auto &t : tracks) {
        const double left = t.box.x, right = t.box.x + t.box.width, bottom = t.box.y + t.box.height;
        const double centre = 0.5 * (left + right);
        double share = NAN;
        const double xl = lanes.ego_left.x_at(float(bottom)), xr = lanes.ego_right.x_at(float(bottom));
        if (lanes.valid && std::isfinite(xl) && std::isfinite(xr) && xr > xl) {
            t.lane_index = int(std::floor((centre - xl) / (xr - xl)));
            share = overlap_share(left, right, xl, xr);
        } else if (std::isfinite(t.lateral_m) && std::isfinite(t.range_m)) {
            const double half_w = 0.5 * t.box.width * t.range_m / cam_.fx;  // vehicle half width, m
            double path_x = 0.0;
            if (std::isfinite(ego.speed_mps) && std::isfinite(ego.yaw_rate_rps) && ego.speed_mps > 1.0)
                path_x = -0.5 * (ego.yaw_rate_rps / ego.speed_mps) * t.range_m * t.range_m;
            const double rel = t.lateral_m - path_x;
            t.lane_index = int(std::lround(rel / p_.lane_width_m));
            share = overlap_share(rel - half_w, rel + half_w, -0.5 * p_.lane_width_m, 0.5 * p_.lane_width_m);
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
