#include "lanes/lane_tracker.hpp"

#include <algorithm>
#include <cmath>

namespace hw {

LaneTracker::LaneTracker(const LaneParams &p, const CameraParams &cam) : p_(p), cam_(cam) {
    prior_ = camera_horizon(cam_, p_.assembly.horizon_tolerance_deg);
    set_rows();
    reset();
}

void LaneTracker::set_search_window(const CameraParams &cam, double tol_deg) {
    prior_ = camera_horizon(cam, tol_deg);
    if (tracks_.empty()) set_rows();  // no track holds its columns at the old rows
}

void LaneTracker::set_rows() {
    yb_ = float(cam_.height - 1);
    // Second row a third of the way from the bottom to the horizon: inside the scanned band, far
    // enough from the bottom that the two rows pin the slope down.
    yr_ = yb_ - (yb_ - std::clamp(prior_.row, 0.f, yb_)) / 3.f;
    if (yb_ - yr_ < 2.f) yr_ = yb_ - 2.f;
}

void LaneTracker::reset() {
    tracks_.clear();
    next_id_ = 0;
    ego_left_id_ = ego_right_id_ = -1;
    width_k_ = kNaN;
    width_age_ = 0;
    vp_ = {kNaN, kNaN};
    frames_since_observed_ = 0;
    curve_ = LaneCurveState();
}

ImageLine LaneTracker::line_of(const Track &t) const {
    return {t.b.x, yb_, (t.r.x - t.b.x) / (yr_ - yb_)};
}

void LaneTracker::set_line(Track &t, const ImageLine &l) const {
    t.b.x = l.x_at(yb_);
    t.r.x = l.x_at(yr_);
}

void LaneTracker::RowFilter::init(float z, float r, float v_var) {
    x = z; v = 0.f;
    p00 = r; p01 = 0.f; p11 = v_var;
}

// x' = x + v; P' = F P F^T + Q, Q = q^2 [[1/4, 1/2], [1/2, 1]] (white acceleration, one frame).
void LaneTracker::RowFilter::predict(float q) {
    x += v;
    const float q2 = q * q;
    p00 += 2.f * p01 + p11 + 0.25f * q2;
    p01 += p11 + 0.5f * q2;
    p11 += q2;
}

// K = P H^T / (H P H^T + r), H = [1 0]; x += K (z - x); P = (I - K H) P.
void LaneTracker::RowFilter::update(float z, float r) {
    const float s = p00 + r, k0 = p00 / s, k1 = p01 / s, res = z - x;
    x += k0 * res;
    v += k1 * res;
    p11 -= k1 * p01;
    p01 *= 1.f - k0;
    p00 *= 1.f - k0;
}

// Predict every track (constant velocity), then match measured lines to tracks greedily by the
// larger of the two row distances in lane widths, within the gate, and update each row's Kalman
// filter with the measured column; its variance comes from the line's fit at that row.
void LaneTracker::associate(const LaneMeasurement &m, const HorizonPrior &hp) {
    const float q = float(p_.process_accel_frac) * float(cam_.width);
    for (auto &t : tracks_) {
        t.b.predict(q);
        t.r.predict(q);
    }
    const float s2 = float(p_.marking_sigma_px * p_.marking_sigma_px);
    auto meas_var = [&](const LaneCandidate &c, float y) {
        const float rel = c.fit.rel_sigma_at(y);
        return std::isfinite(rel) ? s2 * rel * rel : 100.f * s2;
    };
    const float lw = float(p_.assembly.road.lane_width_m);
    const float wb = std::max(1.f, lw * px_per_m(cam_, hp.row, yb_));
    const float wr = std::max(1.f, lw * px_per_m(cam_, hp.row, yr_));
    struct Pair { float d; size_t t, m; };
    std::vector<Pair> pairs;
    for (size_t i = 0; i < tracks_.size(); ++i)
        for (size_t j = 0; j < m.lines.size(); ++j) {
            const ImageLine &l = m.lines[j].line;
            const float d = std::max(std::fabs(l.x_at(yb_) - tracks_[i].b.x) / wb,
                                     std::fabs(l.x_at(yr_) - tracks_[i].r.x) / wr);
            if (d < float(p_.gate_lanes)) pairs.push_back({d, i, j});
        }
    std::sort(pairs.begin(), pairs.end(), [](const Pair &a, const Pair &b) { return a.d < b.d; });
    std::vector<char> t_used(tracks_.size(), 0), m_used(m.lines.size(), 0);
    for (const auto &pr : pairs) {
        if (t_used[pr.t] || m_used[pr.m]) continue;
        t_used[pr.t] = m_used[pr.m] = 1;
        Track &t = tracks_[pr.t];
        const LaneCandidate &c = m.lines[pr.m];
        t.b.update(c.line.x_at(yb_), meas_var(c, yb_));
        t.r.update(c.line.x_at(yr_), meas_var(c, yr_));
        ++t.hits;
        t.missing = 0;
    }
    for (size_t i = 0; i < tracks_.size(); ++i)
        if (!t_used[i]) {
            Track &t = tracks_[i];
            ++t.missing;
            t.b.v *= 0.5f;  // coast, but do not extrapolate a motion that is no longer seen
            t.r.v *= 0.5f;
        }
    tracks_.erase(std::remove_if(tracks_.begin(), tracks_.end(),
                                 [&](const Track &t) { return t.missing > p_.max_missing_frames; }),
                  tracks_.end());
    for (size_t j = 0; j < m.lines.size(); ++j) {
        if (m_used[j]) continue;
        Track t;
        t.id = next_id_++;
        const LaneCandidate &c = m.lines[j];
        const float v_var = (0.01f * float(cam_.width)) * (0.01f * float(cam_.width));  // ~6 px/frame at 640
        t.b.init(c.line.x_at(yb_), meas_var(c, yb_), v_var);
        t.r.init(c.line.x_at(yr_), meas_var(c, yr_), v_var);
        t.hits = 1;
        tracks_.push_back(t);
    }
    // Keep the best-established tracks when there are too many.
    if (int(tracks_.size()) > p_.max_tracks) {
        std::stable_sort(tracks_.begin(), tracks_.end(), [](const Track &x, const Track &y) {
            return x.hits - 3 * x.missing > y.hits - 3 * y.missing;
        });
        tracks_.resize(size_t(p_.max_tracks));
    }
}

// Search around the tracked vanishing point, kept within the camera prior's window.
HorizonPrior LaneTracker::search_prior() const {
    HorizonPrior hp = prior_;
    if (std::isfinite(vp_.x) && std::isfinite(vp_.y)) {
        hp.row = std::clamp(vp_.y, prior_.row - prior_.tol_px, prior_.row + prior_.tol_px);
        hp.vp_x = std::clamp(vp_.x, 0.f, float(cam_.width - 1));
    }
    return hp;
}

// Tracks -> candidates for the assignment; evidence grows with history and fades while coasting.
std::vector<LaneCandidate> LaneTracker::candidates() const {
    std::vector<LaneCandidate> cands;
    for (const auto &t : tracks_) {
        LaneCandidate c;
        c.line = line_of(t);
        c.weight = float(std::min(t.hits, 10)) * (1.f - float(t.missing) / float(p_.max_missing_frames + 1));
        c.observed = t.missing == 0;
        c.id = t.id;
        cands.push_back(c);
    }
    return cands;
}

// The tracked ego width learns from frames measuring both boundaries; an ego boundary that is not
// measured while its partner is moves with the partner at that width (a vehicle hides it while the
// car drifts), and one with no track at all (just crossed into a new lane) is carried at that width.
void LaneTracker::carry_ego_width(std::vector<LaneCandidate> &cands, LaneAssignment &a, cv::Point2f vp) {
    const bool width_fresh = std::isfinite(width_k_) && width_age_ <= p_.max_missing_frames;
    const bool have_l = a.ego_left >= 0, have_r = a.ego_right >= 0;
    if (have_l && have_r) {
        LaneCandidate &l = cands[size_t(a.ego_left)], &r = cands[size_t(a.ego_right)];
        if (l.observed && r.observed) {
            const float w = r.line.k - l.line.k;
            width_k_ = std::isfinite(width_k_) ? width_k_ + float(p_.width_alpha) * (w - width_k_) : w;
            width_age_ = 0;
            return;
        }
        if (width_fresh && std::isfinite(vp.y) && (l.observed || r.observed)) {
            LaneCandidate &hidden = l.observed ? r : l;
            const LaneCandidate &seen = l.observed ? l : r;
            hidden.line = shifted_by_lanes(seen.line, l.observed ? 1.f : -1.f, width_k_, vp);
            for (auto &t : tracks_)
                if (t.id == hidden.id) set_line(t, hidden.line);
        }
    } else if ((have_l || have_r) && width_fresh && std::isfinite(vp.y)) {
        LaneCandidate v;
        v.line = shifted_by_lanes(cands[size_t(have_l ? a.ego_left : a.ego_right)].line, have_l ? 1.f : -1.f,
                                  width_k_, vp);
        v.observed = false;
        cands.push_back(v);
        (have_l ? a.ego_right : a.ego_left) = int(cands.size() - 1);
        a.width_k = width_k_;
    }
    ++width_age_;
}

// Each measured track's support (its share of range bins with paint outside the confirmed vehicles'
// boxes), smoothed; a track not measured this frame keeps its value (a hidden marking is still one).
// The ego boundaries are judged by their curves; the model is certain when both are believed.
void LaneTracker::update_support(const LaneMeasurement &m, const std::vector<TrackState> &vehicles, float y_h,
                                 const ScanBand &band, LaneModel &out) {
    const float y_near = float(band.y_bottom);
    std::vector<cv::Rect2f> boxes;
    for (const auto &v : vehicles)
        if (v.confirmed) boxes.push_back(v.box);
    const float a = float(p_.evidence.alpha);
    float ego_support[2] = {0.f, 0.f};
    for (auto &t : tracks_) {
        const int side = t.id == ego_left_id_ ? 0 : t.id == ego_right_id_ ? 1 : -1;
        if (t.missing == 0) {
            LaneBoundary b = side == 0 ? out.ego_left : side == 1 ? out.ego_right : LaneBoundary();
            if (side < 0) {
                const ImageLine l = line_of(t);
                b.valid = true;
                b.bottom = {l.x_at(yb_), yb_};
                b.top = {l.x_at(yr_), yr_};
            }
            const float s = boundary_support(b, m.points, boxes, y_h, y_near, cam_, p_.evidence);
            t.support = std::isfinite(t.support) ? t.support + a * (s - t.support) : s;
        }
        if (side >= 0 && std::isfinite(t.support)) ego_support[side] = t.support;
    }
    const float need = float(p_.evidence.min_support);
    out.certain = out.valid && ego_support[0] >= need && ego_support[1] >= need;
    drop_unsupported_outer(out, m.points, boxes, y_h, y_near, cam_, p_.evidence);
    // The carriageway ends at a solid ego boundary (lane_evidence.hpp, solid_edge_min_rows).
    drop_beyond_solid_edges(out, m.points, boxes, y_h, band, cam_, p_.evidence);
}

void LaneTracker::update(const cv::Mat &gray, LaneModel &out, const std::vector<TrackState> &vehicles) {
    const HorizonPrior hp = search_prior();
    const bool have_vp = std::isfinite(vp_.x) && std::isfinite(vp_.y);
    const cv::Point2f known_vp(hp.vp_x, hp.row);
    hidden_.clear();
    if (p_.reject_in_vehicles)
        for (const auto &v : vehicles)
            if (v.confirmed) hidden_.push_back(v.box);
    const LaneMeasurement m = measure_lane_lines(gray, p_, cam_, hp, have_vp ? &known_vp : nullptr, &hidden_, true);
    associate(m, hp);

    std::vector<LaneCandidate> cands = candidates();
    const bool width_fresh = std::isfinite(width_k_) && width_age_ <= p_.max_missing_frames;
    LaneAssignment a = assign_lanes(cands, cam_, p_.assembly, ego_left_id_, ego_right_id_,
                                    width_fresh ? width_k_ : kNaN);
    carry_ego_width(cands, a, have_vp ? vp_ : m.vp);
    const bool both = a.ego_left >= 0 && a.ego_right >= 0;

    // Vanishing point: where the tracked ego boundaries meet; else this frame's consensus, smoothed.
    cv::Point2f q;
    if (both && intersect(cands[size_t(a.ego_left)].line, cands[size_t(a.ego_right)].line, q) &&
        std::fabs(q.y - prior_.row) <= prior_.tol_px) {
        vp_ = q;
    } else if (std::isfinite(m.vp.x)) {
        vp_ = have_vp ? vp_ + 0.5f * (m.vp - vp_) : m.vp;
    } else if (tracks_.empty()) {
        vp_ = {kNaN, kNaN};
    }

    ego_left_id_ = a.ego_left >= 0 ? cands[size_t(a.ego_left)].id : -1;
    ego_right_id_ = a.ego_right >= 0 ? cands[size_t(a.ego_right)].id : -1;
    const bool both_observed = both && cands[size_t(a.ego_left)].observed && cands[size_t(a.ego_right)].observed;
    frames_since_observed_ = both_observed ? 0 : frames_since_observed_ + 1;

    out = LaneModel();
    build_lane_model(cands, a, vp_, gray.size(), cam_, hp, p_.assembly, out);
    out.frames_since_observed = frames_since_observed_;
    const float y_h = std::isfinite(out.vanishing_point.y) ? out.vanishing_point.y : hp.row;
    fit_lane_curves(m.points, y_h, cam_, float(p_.assembly.road.lane_width_m), p_.curve, curve_, out);
    ego_lane_metrics(cam_, out);
    update_support(m, vehicles, y_h, scan_band(gray.size(), cam_, hp, p_.filter), out);
}

} // namespace hw
