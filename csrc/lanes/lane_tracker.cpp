#include "lanes/lane_tracker.hpp"

#include <algorithm>
#include <cmath>
#include <stdexcept>
#include <string>

namespace hw {

namespace {

void check_frame(const cv::Mat &gray, const CameraParams &cam) {
    if (gray.empty() || gray.type() != CV_8UC1)
        throw std::invalid_argument("lanes: expected a non-empty 8-bit gray image");
    if (gray.cols != cam.width || gray.rows != cam.height)
        throw std::invalid_argument("lanes: frame is " + std::to_string(gray.cols) + "x" + std::to_string(gray.rows) +
                                    " but the camera is configured for " + std::to_string(cam.width) + "x" +
                                    std::to_string(cam.height));
}

} // namespace

namespace {

std::vector<LaneCandidate> hough_candidates(const std::vector<MarkingPoint> &pts, const ScanBand &band,
                                            cv::Size size, const CameraParams &cam, const HorizonPrior &hp,
                                            const LaneParams &p, const HoughWindow &win) {
    std::vector<LaneCandidate> out;
    for (const auto &l : hough_lane_lines(pts, band, size, cam, hp, p.hough, win)) {
        LaneCandidate c;
        c.line = l.line;
        c.weight = l.votes;
        c.fit = l.fit;
        out.push_back(c);
    }
    return out;
}

// Keeps the lines through the consensus vanishing point (if any), which is written to vp.
bool keep_consensus(std::vector<LaneCandidate> &lines, const HorizonPrior &hp, cv::Size size,
                    const LaneAssemblyParams &p, cv::Point2f &vp) {
    std::vector<char> inlier;
    if (!consensus_vanishing_point(lines, hp, size, p, vp, inlier)) return false;
    std::vector<LaneCandidate> kept;
    for (size_t i = 0; i < lines.size(); ++i)
        if (inlier[i]) kept.push_back(lines[i]);
    lines.swap(kept);
    return true;
}

} // namespace

// Two passes: the strong lines in a wide window give the vanishing point by consensus (skipped
// when the caller knows it), then every marking is searched in a narrow window around it.
LaneMeasurement measure_lane_lines(const cv::Mat &gray, const LaneParams &p, const CameraParams &cam,
                                   const HorizonPrior &hp, const cv::Point2f *known_vp) {
    check_frame(gray, cam);
    LaneMeasurement m;
    const ScanBand band = scan_band(gray.size(), cam, hp, p.filter);
    if (band.rows() < 2) return m;
    std::vector<MarkingPoint> pts;
    find_marking_points(gray, band, cam, hp, p.filter, pts);

    // Narrow search around vp: the lines through it, with the vanishing point refined by them.
    auto narrow = [&](cv::Point2f vp, bool tracked) {
        m.lines = hough_candidates(pts, band, gray.size(), cam, hp, p, vp_window(vp, tracked, gray.size(), p.hough));
        cv::Point2f refined;
        m.vp = keep_consensus(m.lines, hp, gray.size(), p.assembly, refined) ? refined : vp;
    };
    if (known_vp) {
        narrow(*known_vp, true);
        if (m.lines.size() >= 2) return m;
    }
    // The vanishing point of this frame (or the known one found too little: it moved, or the road
    // changed): consensus of the strong lines of a wide search.
    std::vector<LaneCandidate> wide =
        hough_candidates(pts, band, gray.size(), cam, hp, p, wide_window(gray.size(), hp, p.hough));
    cv::Point2f vp;
    if (keep_consensus(wide, hp, gray.size(), p.assembly, vp)) {
        narrow(vp, false);
        if (m.lines.empty()) m.lines = wide;
    } else {
        m.lines = wide;  // no two lines agree: keep them all, vanishing point unknown
        m.vp = {kNaN, kNaN};
    }
    return m;
}

LaneModel detect_lanes(const cv::Mat &gray, const LaneParams &p, const CameraParams &cam) {
    const HorizonPrior hp = camera_horizon(cam, p.assembly.horizon_tolerance_deg);
    const LaneMeasurement m = measure_lane_lines(gray, p, cam, hp);
    const LaneAssignment a = assign_lanes(m.lines, cam, p.assembly);
    LaneModel out;
    build_lane_model(m.lines, a, m.vp, gray.size(), cam, hp, p.assembly, out);
    out.frames_since_observed = out.valid ? 0 : 1;
    return out;
}

LaneTracker::LaneTracker(const LaneParams &p, const CameraParams &cam) : p_(p), cam_(cam) {
    prior_ = camera_horizon(cam_, p_.assembly.horizon_tolerance_deg);
    yb_ = float(cam_.height - 1);
    // Second row a third of the way from the bottom to the horizon: inside the scanned band, far
    // enough from the bottom that the two rows pin the slope down.
    yr_ = yb_ - (yb_ - std::clamp(prior_.row, 0.f, yb_)) / 3.f;
    if (yb_ - yr_ < 2.f) yr_ = yb_ - 2.f;
    reset();
}

void LaneTracker::reset() {
    tracks_.clear();
    next_id_ = 0;
    ego_left_id_ = ego_right_id_ = -1;
    width_k_ = kNaN;
    width_age_ = 0;
    vp_ = {kNaN, kNaN};
    frames_since_observed_ = 0;
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
    const float lw = float(p_.assembly.lane_width_m);
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

void LaneTracker::update(const cv::Mat &gray, LaneModel &out) {
    check_frame(gray, cam_);
    // Search around the tracked vanishing point, kept within the camera prior's window.
    HorizonPrior hp = prior_;
    const bool have_vp = std::isfinite(vp_.x) && std::isfinite(vp_.y);
    if (have_vp) {
        hp.row = std::clamp(vp_.y, prior_.row - prior_.tol_px, prior_.row + prior_.tol_px);
        hp.vp_x = std::clamp(vp_.x, 0.f, float(cam_.width - 1));
    }
    const cv::Point2f known_vp(hp.vp_x, hp.row);
    const LaneMeasurement m = measure_lane_lines(gray, p_, cam_, hp, have_vp ? &known_vp : nullptr);
    associate(m, hp);

    // Tracks -> candidates; evidence grows with history and fades while a track coasts.
    std::vector<LaneCandidate> cands;
    for (const auto &t : tracks_) {
        LaneCandidate c;
        c.line = line_of(t);
        c.weight = float(std::min(t.hits, 10)) * (1.f - float(t.missing) / float(p_.max_missing_frames + 1));
        c.observed = t.missing == 0;
        c.id = t.id;
        cands.push_back(c);
    }
    const bool width_fresh = std::isfinite(width_k_) && width_age_ <= p_.max_missing_frames;
    LaneAssignment a = assign_lanes(cands, cam_, p_.assembly, ego_left_id_, ego_right_id_,
                                    width_fresh ? width_k_ : kNaN);
    const cv::Point2f vp_ref = std::isfinite(vp_.x) ? vp_ : m.vp;

    if (a.ego_left >= 0 && a.ego_right >= 0) {
        LaneCandidate &l = cands[size_t(a.ego_left)], &r = cands[size_t(a.ego_right)];
        if (l.observed && r.observed) {
            const float w = r.line.k - l.line.k;
            width_k_ = std::isfinite(width_k_) ? width_k_ + float(p_.width_alpha) * (w - width_k_) : w;
            width_age_ = 0;
        } else if (width_fresh && std::isfinite(vp_ref.y) && (l.observed || r.observed)) {
            // One boundary hidden: it moves with the visible one at the tracked width.
            LaneCandidate &hidden = l.observed ? r : l;
            const LaneCandidate &seen = l.observed ? l : r;
            const float n = l.observed ? 1.f : -1.f;
            hidden.line.k = seen.line.k + n * width_k_;
            hidden.line.x_ref = seen.line.x_ref + n * width_k_ * (seen.line.y_ref - vp_ref.y);
            for (auto &t : tracks_)
                if (t.id == hidden.id) set_line(t, hidden.line);
        }
    } else if ((a.ego_left >= 0 || a.ego_right >= 0) && width_fresh && std::isfinite(vp_ref.y)) {
        // One side has no track at all (just crossed into a new lane, or it timed out while the
        // width is still known): carry it at the tracked width, as not observed.
        const bool have_left = a.ego_left >= 0;
        const LaneCandidate seen = cands[size_t(have_left ? a.ego_left : a.ego_right)];
        LaneCandidate v;
        const float n = have_left ? 1.f : -1.f;
        v.line = seen.line;
        v.line.k = seen.line.k + n * width_k_;
        v.line.x_ref = seen.line.x_ref + n * width_k_ * (seen.line.y_ref - vp_ref.y);
        v.observed = false;
        cands.push_back(v);
        (have_left ? a.ego_right : a.ego_left) = int(cands.size() - 1);
        a.width_k = width_k_;
    }
    if (!(a.ego_left >= 0 && a.ego_right >= 0 && cands[size_t(a.ego_left)].observed &&
          cands[size_t(a.ego_right)].observed))
        ++width_age_;

    // Vanishing point: where the tracked ego boundaries meet; else the frame's consensus, smoothed.
    cv::Point2f q;
    if (a.ego_left >= 0 && a.ego_right >= 0 &&
        intersect(cands[size_t(a.ego_left)].line, cands[size_t(a.ego_right)].line, q) &&
        std::fabs(q.y - prior_.row) <= prior_.tol_px) {
        vp_ = q;
    } else if (std::isfinite(m.vp.x)) {
        vp_ = std::isfinite(vp_.x) ? vp_ + 0.5f * (m.vp - vp_) : m.vp;
    } else if (tracks_.empty()) {
        vp_ = {kNaN, kNaN};
    }

    ego_left_id_ = a.ego_left >= 0 ? cands[size_t(a.ego_left)].id : -1;
    ego_right_id_ = a.ego_right >= 0 ? cands[size_t(a.ego_right)].id : -1;
    const bool both_observed = a.ego_left >= 0 && a.ego_right >= 0 && cands[size_t(a.ego_left)].observed &&
                               cands[size_t(a.ego_right)].observed;
    frames_since_observed_ = both_observed ? 0 : frames_since_observed_ + 1;

    out = LaneModel();
    build_lane_model(cands, a, vp_, gray.size(), cam_, hp, p_.assembly, out);
    out.frames_since_observed = frames_since_observed_;
}

} // namespace hw
