#include "geometry/track_kinematics.hpp"

#include "geometry/flat_road.hpp"

#include <cmath>
#include <unordered_set>

namespace hw {

namespace {

// Least-squares slope of y over t.
double slope(const std::deque<std::pair<double, double>> &pts) {
    double st = 0, sy = 0;
    for (const auto &p : pts) { st += p.first; sy += p.second; }
    const double n = double(pts.size()), mt = st / n, my = sy / n;
    double num = 0, den = 0;
    for (const auto &p : pts) {
        num += (p.first - mt) * (p.second - my);
        den += (p.first - mt) * (p.first - mt);
    }
    return den > 0 ? num / den : NAN;
}

} // namespace

void TrackKinematics::update(std::vector<TrackState> &tracks, double horizon_row, double t_s) {
    std::unordered_set<int> seen;
    for (auto &tr : tracks) {
        const float u = tr.box.x + 0.5f * tr.box.width, v = tr.box.y + tr.box.height;
        const RoadPoint rp = road_point(cam_, u, v, horizon_row);
        if (!rp.valid()) continue;  // contact row at or above the horizon: no range
        const double row_sigma = std::max(p_.min_row_sigma_px, std::isfinite(tr.bottom_sigma_px) ? double(tr.bottom_sigma_px) : 0.0);
        const double r_sigma = range_sigma(cam_, rp.z_m, row_sigma);
        tr.range_m = float(rp.z_m);
        tr.range_sigma_m = float(r_sigma);
        tr.lateral_m = float(rp.x_m);
        if (tr.id < 0) continue;  // single-image detections carry no history
        seen.insert(tr.id);

        auto it = state_.find(tr.id);
        if (it == state_.end()) {
            State s;
            s.z = rp.z_m;
            s.vz = 0;
            s.p00 = r_sigma * r_sigma;
            s.p11 = 100.0;  // (10 m/s)^2: range rate unknown at birth
            s.t = t_s;
            it = state_.emplace(tr.id, s).first;
        } else {
            State &s = it->second;
            const double dt = std::max(1e-3, t_s - s.t);
            // predict: x' = F x, P' = F P F^T + Q with F = [1 dt; 0 1], Q = q [dt^4/4 dt^3/2; dt^3/2 dt^2]
            const double q = p_.accel_sigma_mps2 * p_.accel_sigma_mps2;
            s.z += s.vz * dt;
            const double p00 = s.p00 + 2 * dt * s.p01 + dt * dt * s.p11 + q * dt * dt * dt * dt / 4;
            const double p01 = s.p01 + dt * s.p11 + q * dt * dt * dt / 2;
            const double p11 = s.p11 + q * dt * dt;
            // update with the range measurement: K = P H^T (H P H^T + R)^-1, H = [1 0]
            const double sk = p00 + r_sigma * r_sigma;
            const double k0 = p00 / sk, k1 = p01 / sk;
            const double innov = rp.z_m - s.z;
            s.z += k0 * innov;
            s.vz += k1 * innov;
            s.p00 = (1 - k0) * p00;
            s.p01 = (1 - k0) * p01;
            s.p11 = p11 - k1 * p01;
            s.t = t_s;
        }
        State &s = it->second;
        // Range rate only once the filter has seen some motion (its variance has come down).
        if (s.p11 < 4.0) tr.range_rate_mps = float(s.vz);
        const double closing = -s.vz;
        if (s.p11 < 4.0 && closing > p_.min_closing_mps)
            tr.ttc_s = float(std::max(0.0, s.z - p_.ego_front_m) / closing);

        if (tr.box.width > 1.f) {
            s.log_w.emplace_back(t_s, std::log(double(tr.box.width)));
            while (int(s.log_w.size()) > p_.scale_window) s.log_w.pop_front();
            if (s.log_w.size() >= 3 && s.log_w.back().first - s.log_w.front().first >= p_.scale_min_span_s) {
                const double rate = slope(s.log_w);  // d(ln w)/dt = 1 / TTC to the camera plane
                if (std::isfinite(rate) && rate * s.z > p_.min_closing_mps) {
                    // to the bumper: the camera-plane TTC scaled by the share of range left to the bumper
                    tr.ttc_scale_s = float(std::max(0.0, s.z - p_.ego_front_m) / s.z / rate);
                }
            }
        }
    }
    for (auto it = state_.begin(); it != state_.end();)
        it = seen.count(it->first) ? std::next(it) : state_.erase(it);
}

} // namespace hw
