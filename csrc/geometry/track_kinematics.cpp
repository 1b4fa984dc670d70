#include "geometry/track_kinematics.hpp"

#include "geometry/flat_road.hpp"

#include <cmath>
#include <unordered_set>

namespace hw {

namespace {

// The UKF's rate, before it settles, lags a sudden closing by more than its sigma says: up to 3.5 sigma on the
// stopped car of stopped_lead_100kmh, whose scale TTC is right. A scale TTC further than this from it is refused.
constexpr double kUnsettledRateSigmas = 4.0;

// Least-squares slope of y over t, and its standard error (from the residuals).
double slope(const std::deque<std::pair<double, double>> &pts, double &std_error) {
    double st = 0, sy = 0;
    for (const auto &p : pts) { st += p.first; sy += p.second; }
    const double n = double(pts.size()), mt = st / n, my = sy / n;
    double num = 0, den = 0;
    for (const auto &p : pts) {
        num += (p.first - mt) * (p.second - my);
        den += (p.first - mt) * (p.first - mt);
    }
    if (den <= 0) return NAN;
    const double b = num / den;
    double ss = 0;
    for (const auto &p : pts) {
        const double r = p.second - my - b * (p.first - mt);
        ss += r * r;
    }
    std_error = n > 2 ? std::sqrt(ss / (n - 2) / den) : INFINITY;
    return b;
}

} // namespace

double TrackKinematics::scale_fit(const TrackState &tr, State &s, double t_s, double range_m, double &scale_se) const {
    const double width = double(tr.box.width) - p_.scale_margin_px;  // the vehicle's rear, without the margin
    if (width > 1.0) {
        const double lw = std::log(width);
        // A width step no vehicle can make in one frame (closing at scale_jump_closing_mps at this range, plus
        // scale_jump_px of edge noise) is the box changing, not the vehicle: the window restarts after it. Fitted
        // through, one 20 % step on a car 51 m ahead (TME tme08, the detector's box taking in its flank) read as
        // closing at 24 m/s, TTC 1.9 s, while the range said 8 m/s.
        if (!s.log_w.empty() && std::isfinite(range_m) && range_m > 0.0) {
            const double dt = std::max(0.0, t_s - s.log_w.back().first);
            const double limit = p_.scale_jump_closing_mps * dt / range_m + p_.scale_jump_px / width;
            if (std::fabs(lw - s.log_w.back().second) > limit) s.log_w.clear();
        }
        s.log_w.emplace_back(t_s, lw);
        while (int(s.log_w.size()) > p_.scale_window) s.log_w.pop_front();
        if (int(s.log_w.size()) >= p_.scale_window && s.log_w.back().first - s.log_w.front().first >= p_.scale_min_span_s)
            return slope(s.log_w, scale_se);
    }
    return NAN;
}

void TrackKinematics::given_range_ttcs(TrackState &tr, State &s, double t_s) const {
    const double z = tr.range_m, estimate = tr.range_rate_mps, sigma = tr.range_rate_sigma_mps;
    // the tracker's rate is reported once it has settled (sigma NaN: the tracker vouches for it)
    const bool rate_known = std::isfinite(estimate) && !(sigma >= kRateKnownSigma);
    if (!rate_known) tr.range_rate_mps = NAN;
    if (rate_known && -estimate > p_.min_closing_mps) tr.ttc_s = float(std::max(0.0, z - p_.ego_front_m) / -estimate);
    double se = NAN;
    const double scale_rate = scale_fit(tr, s, t_s, z, se);
    // The scale TTC as below, checked against the tracker's rate: once settled within 3 (z se + 1 m/s); before,
    // within kUnsettledRateSigmas sigma of both. A far car's box growing by 3 px in 0.4 s (solidWhiteRight with
    // fuse.small_box_px 24, 77 m ahead: 21 m/s of closing, TTC 3.5 s) is then refused by a rate of -4.6 +- 2.4
    // m/s (6-7 sigma).
    const double innov = -z * scale_rate - estimate;
    const double k = kUnsettledRateSigmas;
    const bool agrees = !std::isfinite(estimate) ||
                        (rate_known ? std::fabs(innov) <= 3.0 * (z * se + 1.0)
                                    : innov * innov <= k * k * (sigma * sigma + z * se * z * se));
    if (std::isfinite(scale_rate) && z * scale_rate > p_.min_closing_mps && scale_rate > 3.0 * se && agrees)
        tr.ttc_scale_s = float(std::max(0.0, z - p_.ego_front_m) / z / scale_rate);
}

void TrackKinematics::update(std::vector<TrackState> &tracks, double horizon_row, double t_s) {
    std::unordered_set<int> seen;
    for (auto &tr : tracks) {
        if (std::isfinite(tr.range_m) && tr.id >= 0) {
            // The tracker estimated range, lateral and range rate itself (the phd preset's UKF): only the TTCs.
            seen.insert(tr.id);
            given_range_ttcs(tr, state_[tr.id], t_s);
            continue;
        }
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
            s.x << rp.z_m, 0.0, 0.0;
            // range as measured; range rate and acceleration unknown at birth: (15 m/s)^2, (5 m/s^2)^2
            s.P = Eigen::Vector3d(r_sigma * r_sigma, 225.0, 25.0).asDiagonal();
            s.t = t_s;
            it = state_.emplace(tr.id, s).first;
        } else {
            State &s = it->second;
            const double dt = std::max(1e-3, t_s - s.t);
            // predict: x' = F x, P' = F P F^T + Q, constant acceleration, white jerk of variance q:
            // Q = q [dt^5/20 dt^4/8 dt^3/6; dt^4/8 dt^3/3 dt^2/2; dt^3/6 dt^2/2 dt]
            Eigen::Matrix3d F;
            F << 1, dt, 0.5 * dt * dt, 0, 1, dt, 0, 0, 1;
            const double q = p_.jerk_sigma_mps3 * p_.jerk_sigma_mps3;
            const double d2 = dt * dt, d3 = d2 * dt, d4 = d3 * dt, d5 = d4 * dt;
            Eigen::Matrix3d Q;
            Q << d5 / 20, d4 / 8, d3 / 6, d4 / 8, d3 / 3, d2 / 2, d3 / 6, d2 / 2, dt;
            s.x = F * s.x;
            s.P = F * s.P * F.transpose() + q * Q;
            // update with the range: K = P H^T / (H P H^T + R), H = [1 0 0]
            const double sk = s.P(0, 0) + r_sigma * r_sigma;
            const Eigen::Vector3d K = s.P.col(0) / sk;
            s.x += K * (rp.z_m - s.x(0));
            s.P -= K * s.P.row(0);
            s.t = t_s;
        }
        State &s = it->second;

        // The scale change of the box: d(ln w)/dt over the last scale_window frames (a full window
        // only: while a track is young its box is still settling).
        double scale_se = NAN;
        const double scale_rate = scale_fit(tr, s, t_s, s.x(0), scale_se);
        // The scale change measures the range rate too, independently of the horizon: dZ/dt = -Z d(ln w)/dt
        // (used by the filter only with scale_rate_fusion; the agreement check below always).
        // The range alone swings with every error of the horizon row (on a real clip the lane vanishing
        // point moves by +-7 px while the car's box stays put); the width does not. Consecutive windows
        // overlap, so each fit counts as scale_window times less certain. A fit the filter finds
        // implausible (beyond 3 sigma of both) is a box that jumped, not a vehicle that did, and is left out.
        bool scale_agrees = false;
        if (std::isfinite(scale_rate) && std::isfinite(scale_se)) {
            const double z = s.x(0);
            const double innov = -z * scale_rate - s.x(1);
            const double z_se2 = (z * scale_se) * (z * scale_se);
            // the stand-in check below: the fit against the filter before the fit has touched it
            scale_agrees = innov * innov <= 9.0 * (s.P(1, 1) + z_se2);
            // The fit is the mean rate over the window, read as the rate now (H = [0 1 0]): modelling
            // its lag through the acceleration was tried and let the range swings' acceleration noise
            // in (a false warning in cut_in); under 0.3 g braking this reads the rate ~0.2 s late.
            if (p_.scale_rate_fusion) {
                const double sk = s.P(1, 1) + p_.scale_window * z_se2;
                if (innov * innov <= 9.0 * sk) {
                    const Eigen::Vector3d K = s.P.col(1) / sk;
                    s.x += K * innov;
                    s.P -= K * s.P.row(1);
                }
            }
        }

        // Range rate and acceleration only once the filter has converged: variance down to (2 m/s)^2,
        // and for the acceleration to (1.5 m/s^2)^2 with the estimate clear of zero by two sigma
        // (a noisy acceleration would turn every wobble of the box into a braking lead).
        const bool rate_known = s.P(1, 1) < kRateKnownSigma * kRateKnownSigma;
        if (rate_known) tr.range_rate_mps = float(s.x(1));
        if (rate_known && s.P(2, 2) < 2.25 && std::fabs(s.x(2)) > 2.0 * std::sqrt(s.P(2, 2)))
            tr.range_accel_mps2 = float(s.x(2));
        const double closing = -s.x(1);
        if (rate_known && closing > p_.min_closing_mps)
            tr.ttc_s = float(std::max(0.0, s.x(0) - p_.ego_front_m) / closing);
        // The scale TTC on its own (the FCW's stand-in while the rate is unknown, and a check on the
        // range TTC): only a clear scale change, the slope at least 3 standard errors from zero, that
        // the range filter does not contradict (its rate sigma is 15 m/s at birth, so a new track passes;
        // a far box whose width wobbles by a pixel claims tens of m/s that its range history denies).
        const double z_now = s.x(0);
        if (std::isfinite(scale_rate) && z_now * scale_rate > p_.min_closing_mps && scale_rate > 3.0 * scale_se &&
            (rate_known || scale_agrees)) {
            // to the bumper: the camera-plane TTC scaled by the share of range left to the bumper
            tr.ttc_scale_s = float(std::max(0.0, z_now - p_.ego_front_m) / z_now / scale_rate);
        }
    }
    for (auto it = state_.begin(); it != state_.end();)
        it = seen.count(it->first) ? std::next(it) : state_.erase(it);
    // The tracked vehicles' boxes reported as the vehicles' sides: the learned detector draws its boxes as
    // TuSimple's annotators did, 2-3 px wider than the car for boxes 10-30 px high and 3-5 px at 30-60 px
    // (docs/tracking.md). After the scale fit (which takes its own constant scale_margin_px) and the range,
    // whose bottom centre the symmetric cut leaves where it was. Single-image detections (id < 0) stay as found.
    if (p_.box_margin_px > 0.0 || p_.box_margin_frac > 0.0) {
        for (auto &tr : tracks) {
            if (tr.id < 0) continue;
            const float cut = float(p_.box_margin_px + p_.box_margin_frac * tr.box.height);
            if (tr.box.width > 2.0f * cut) {
                tr.box.x += 0.5f * cut;
                tr.box.width -= cut;
            }
        }
    }
}

} // namespace hw
