#include "track/phd/part.hpp"

#include "base/part_registry.hpp"
#include "base/stopwatch.hpp"
#include "geometry/flat_road.hpp"
#include "track/birth_gate.hpp"
#include "track/duplicate_pruning.hpp"
#include "track/track_deletion.hpp"

#include <algorithm>
#include <cmath>
#include <ctime>

namespace hw {

void PhdTrackerParams::bind(ParamMap &m) {
    m.add("detect_every_n", detect_every_n, 1, 1000,
          "frames; the detector runs on every n-th frame to find new vehicles and re-anchor tracked ones; the "
          "features carry the vehicles in between");
    m.add("detect_lag", detect_lag, 0, 999,
          "frames; >0: each detection runs on a worker thread and is taken this many frames later (at most "
          "detect_every_n - 1); 0: on the frame thread, at once");
    m.add("estimator", estimator, "weights|covariance|max_weight",
          "the vehicle's contact point from its stable features: weights (eq. 13, weight-averaged; the paper's "
          "choice for cost), covariance (eq. 14, weighted by 1/|P|), max_weight (eq. 15, the heaviest feature)");
    m.add("birth_every_n", birth_every_n, 1, 1000,
          "frames; new corners are searched in each box (candidate births, eq. 7) every n-th frame");
    m.add("outlier_px", outlier_px, 0.1, 100.0,
          "px; a followed feature further than this from the vehicle's image motion (median shift and scale) "
          "is not a measurement of the vehicle (road, background, the neighbour's edge)");
    m.add("end_weight", end_weight, 0.0, 1000.0,
          "eq. 12; a vehicle whose PHD weight summed inside its box falls under this has ended (about the "
          "expected number of features it still has)");
    m.add("min_stable", min_stable, 1, 1000,
          "stable features a vehicle needs before they measure its contact point (fewer: the UKF predicts)");
    m.add("min_depth_ratio", min_depth_ratio, 0.0, 1.0,
          "a feature whose row below the horizon is under this share of the contact point's (a point near the "
          "camera's height) gives no contact row: its row error would be divided by this share");
    m.add("expansion_sigma_min", expansion_sigma_min, 0.0, 1.0,
          "least 1-sigma of the frame-to-frame scale of a vehicle's feature cloud, as a range-rate observation of "
          "the UKF (e = (s - 1)/dt = -(dZ/dt)/Z); 0 = the scale is not observed");
    m.add("expansion_independent_points", expansion_independent_points, 1, 1000,
          "points whose scale errors count as independent, at most: the expansion's 1-sigma is the pair ratios' "
          "spread over sqrt(min(points, this)) (docs/tracking.md)");
    m.add("expansion_min_width_px", expansion_min_width_px, 0.0, 10000.0,
          "px; the cloud's expansion is observed only on a vehicle at least this wide: on a narrower (far) one the "
          "points of the road and background around it pass the motion check and bias the scale");
    m.add("contact_sigma_px", contact_sigma_px, 0.01, 100.0,
          "px; 1-sigma of the contact point the features give (R of the UKF); the mean of several LK "
          "points is steadier than one box edge");
    m.add("contact_full_depth", contact_full_depth, 0.0, 1000.0,
          "the features' depth information (sum of k^2) at which their contact point has contact_sigma_px; less (few "
          "features, or high on the vehicle) widens it by sqrt(this / sum); 0 = contact_sigma_px always");
    m.add("detection_sigma_px", detection_sigma_px, 0.01, 100.0,
          "px; 1-sigma of a detection's contact point (bottom centre of its box) as a UKF measurement");
    m.add("detection_gate_sigma", detection_gate_sigma, 0.0, 100.0,
          "a paired detection whose contact row lies farther than this many sigmas from the vehicle's predicted one "
          "confirms the vehicle but does not measure it (a box reaching into the road's shadow); 0 = no gate");
    m.add("anchor_gain", anchor_gain, 0.0, 1.0,
          "share of a matched detection's box (width, contact point) taken into the vehicle's box and its "
          "features' offsets: the detector keeps the feature cloud's scale from drifting");
    association.bind(m);
    m.add("duplicate_iou", duplicate_iou, 0.0, 1.0,
          "IoU above which two vehicles are the same; the one with fewer detections goes");
    m.add("nearer_below", nearer_below, 0.0, 10.0,
          "box heights; a detection standing this much lower than a vehicle's box across its columns is a nearer "
          "vehicle, not part of it, and may start one; a vehicle almost inside a confirmed nearer one's box goes "
          "(hidden); 0 = neither");
    m.add("confirm_hits", confirm_hits, 1, 100, "detections (the first included) before a vehicle is confirmed");
    m.add("birth_min_appearance", birth_min_appearance, 0.0, 1.0,
          "score under which a learned detection starts no vehicle but may still re-anchor a tracked one; other "
          "parts' detections are not affected; 0 = every detection may start one");
    m.add("birth_lanes_beside", birth_lanes_beside, 0, 4,
          "lanes; a detection starts a vehicle only if its bottom centre stands on the ego lane or at most this many "
          "lane widths beside it (the roadside's bushes and signs start none): the lane model's, else the ego path's on "
          "the flat road (road.lane_width_m); 4: as wide as the detectors' scan");
    m.add("max_detection_misses", max_detection_misses, 1, 1000,
          "detector runs in a row that may miss a confirmed vehicle before it is deleted (a tentative one: 1); "
          "at detect_every_n 3 the features alone carry a vehicle for 15 frames");
    m.add("coast_frames", coast_frames, 0, 1000,
          "frames; a confirmed vehicle whose features are all lost at once (a shadow) is carried this long by "
          "its UKF while new corners become its features; 0 = it ends at once (the paper)");
    m.add("coast_min_hits", coast_min_hits, 1, 1000,
          "detections a vehicle needs (one at the detector's last run) before it may coast: a young track that "
          "loses its features is more often no vehicle (docs/tracking.md)");
    m.add("weak_keeps_hidden", weak_keeps_hidden,
          "a weak detection (under high_score) may keep alive a vehicle a nearer one hides (more than coast_max_hidden "
          "of its box); false: only a confident one does (the weak ones there are the nearer one's edge)");
    m.add("coast_max_hidden", coast_max_hidden, 0.0, 1.0,
          "share of a vehicle's box that a nearer vehicle's box may cover while it coasts (coast_frames); more: it "
          "is being hidden, which explains its lost features, and it ends as without coasting");
    m.add("max_dt_s", max_dt_s, 0.01, 100.0, "s; a longer gap between frames drops all vehicles");
}

PhdTracker::PhdTracker(const PhdTrackerParams &p, const CameraParams &cam, const HorizonTracker &horizon)
    : p_(p), cam_(cam), horizon_(horizon), flow_(p.features), pitch_(p.pitch, p.features), clock_(p.max_dt_s) {}

void PhdTracker::reset() {
    vehicles_.clear();
    flow_.reset();
    horizon_.reset();
    pitch_.reset();
    next_id_ = 1;
    frame_ = 0;
    clock_.reset();
    lagged_due_ = -1;  // the pipeline resets the detector set, dropping a running detection
    lagged_vehicles_.clear();
}

void PhdTracker::set_camera(const CameraParams &camera) {
    // The vehicles are ranged with the estimate; the horizon tracker keeps the configured mounting as its prior
    // for frames without lanes: without lanes the lane-based estimate is least sure (false lanes in unmarked
    // congestion pulled its pitch 2.4 deg off, and the birth gate's road with it).
    for (Vehicle &v : vehicles_) v.ukf->set_camera(camera);
    cam_ = camera;
}

namespace {

double median(std::vector<double> &v) {
    const auto mid = v.begin() + long(v.size() / 2);
    std::nth_element(v.begin(), mid, v.end());
    return *mid;
}

std::vector<cv::Vec2d> means_of(const GmPhd &phd) {
    std::vector<cv::Vec2d> m;
    for (const GmComponent &g : phd.components()) m.push_back(g.m);
    return m;
}

} // namespace

// Eq. 13-15: the contact point each stable feature implies, fused. A feature's tag t is its offset from the
// contact point in units of the contact's depth below the horizon, d = v_c - v_h (= fy h / Z): a point H
// above the road and X beside the contact is seen at v = v_h + d (1 - H/h), u = u_c + d X/h, so
// t = (X/h, -H/h) is the same at every range and the feature alone gives d = (v - v_h) / (1 + t_y) and the
// contact (u - t_x d, v_h + d). A row error e of the feature becomes e / (1 + t_y) in d: each implied
// contact is weighted by k^2 = (1 + t_y)^2 on top of the estimator's weight, and points near the camera's
// height (k < min_depth_ratio) say nothing about the range and are left out.
bool PhdTracker::contact_from_features(const Vehicle &v, double horizon, cv::Point2d &c, double &depth) const {
    double sw = 0.0, best = -1.0;
    depth = 0.0;
    cv::Vec2d acc(0, 0);
    int n = 0;
    for (const GmComponent &g : v.phd.components()) {
        const double k = 1.0 + g.tag[1];
        if (g.w < p_.phd.stable_weight || k < p_.min_depth_ratio) continue;
        const double d = (g.m[1] - horizon) / k;
        const cv::Vec2d ci(g.m[0] - g.tag[0] * d, horizon + d);
        ++n;
        depth += k * k;
        if (p_.estimator == "max_weight") {
            if (g.w > best) { best = g.w; acc = ci; sw = 1.0; }
            continue;
        }
        const double w = p_.estimator == "covariance" ? k * k * k * k / std::max(1e-12, cv::determinant(g.P))
                                                      : g.w * k * k;
        acc += w * ci;
        sw += w;
    }
    if (n < p_.min_stable || !(sw > 0.0)) return false;
    c = {acc[0] / sw, acc[1] / sw};
    return true;
}

// A feature's tag (see contact_from_features) for the contact point `contact`; (0, 0) at or above the horizon.
cv::Vec2d PhdTracker::tag_of(const cv::Vec2d &m, const cv::Point2d &contact, double horizon) {
    const double d = contact.y - horizon;
    return d > 1.0 ? (m - cv::Vec2d(contact.x, contact.y)) / d : cv::Vec2d(0, 0);
}

void PhdTracker::measure(Vehicle &v, const std::vector<cv::Point2f> &prev, const std::vector<cv::Point2f> &cur,
                         const std::vector<uchar> &ok, const cv::Mat &gray, double horizon, double dt) {
    // The vehicle's image motion from its followed features: median shift, median ratio of distances.
    std::vector<double> dx, dy, ratios, px, py;
    std::vector<size_t> idx;
    for (size_t i = 0; i < prev.size(); ++i)
        if (ok[i]) {
            idx.push_back(i);
            dx.push_back(cur[i].x - prev[i].x);
            dy.push_back(cur[i].y - prev[i].y);
            px.push_back(prev[i].x);
            py.push_back(prev[i].y);
        }
    double s = 1.0;
    cv::Vec2d t(v.motion.x, v.motion.y), c(v.contact.x, v.contact.y - 0.5 * v.height.aspect * v.width);
    if (idx.size() >= 2) {
        t = {median(dx), median(dy)};
        c = {median(px), median(py)};
        for (size_t a = 0; a < idx.size(); ++a)
            for (size_t b = a + 1; b < idx.size(); b += std::max<size_t>(1, idx.size() / 8)) {
                const cv::Point2f d0 = prev[idx[a]] - prev[idx[b]], d1 = cur[idx[a]] - cur[idx[b]];
                const double n0 = std::hypot(d0.x, d0.y);
                if (n0 > 4.0) ratios.push_back(std::hypot(d1.x, d1.y) / n0);
            }
        if (ratios.size() >= 3) s = std::clamp(median(ratios), 0.8, 1.25);
        // the vehicle's shift is the median point's: c moves by t, the rest scales about it
    }
    // The cloud's expansion as a range-rate observation (vehicle_ukf.hpp): e = (s - 1) / dt. The median of
    // pair ratios above is robust but biased by the position noise (|d + n| > |d| on average: ~sigma^2/|d|^2,
    // 3e-4 per frame, 0.5 m/s at 50 m); the ratio of the RMS spreads of the points that move with the vehicle,
    // s_e = sqrt(sum |q - q_mean|^2 / sum |p - p_mean|^2), has the noise in both frames cancel. Its 1-sigma:
    // the pair ratios' spread (1.4826 MAD) over the square root of the points, at least the floor.
    if (p_.expansion_sigma_min > 0.0 && dt > 0.0 && ratios.size() >= 6 && v.width >= p_.expansion_min_width_px) {
        std::vector<cv::Vec2d> P0, P1;
        cv::Vec2d m0(0, 0), m1(0, 0);
        for (size_t i : idx) {
            const cv::Vec2d p(prev[i].x, prev[i].y), z(cur[i].x, cur[i].y);
            const cv::Vec2d r = z - (c + t + s * (p - c));
            if (r.dot(r) > p_.outlier_px * p_.outlier_px) continue;
            P0.push_back(p);
            P1.push_back(z);
            m0 += p;
            m1 += z;
        }
        if (P0.size() >= size_t(std::max(3, p_.min_stable))) {
            m0 *= 1.0 / double(P0.size());
            m1 *= 1.0 / double(P1.size());
            double s0 = 0.0, s1 = 0.0;
            for (size_t i = 0; i < P0.size(); ++i) {
                s0 += (P0[i] - m0).dot(P0[i] - m0);
                s1 += (P1[i] - m1).dot(P1[i] - m1);
            }
            std::vector<double> dev;
            for (double r : ratios) dev.push_back(std::abs(r - s));
            const double independent = std::min(double(P0.size()), double(p_.expansion_independent_points));
            const double sigma = std::max(p_.expansion_sigma_min, 1.4826 * median(dev) / std::sqrt(independent));
            if (s0 > 16.0) v.ukf->update_expansion((std::sqrt(s1 / s0) - 1.0) / dt, sigma / dt);
        }
    }
    v.motion = {t[0], t[1]};
    v.phd.predict(s, c, t);
    if (v.coast > 0) {
        // Coasting (no feature measures it): the UKF's predicted contact, the width at the predicted range.
        const double z0 = v.prev_range;
        v.contact = v.ukf->predicted_contact(horizon);
        if (z0 > 0.0 && v.ukf->range() > 0.0) v.width *= z0 / v.ukf->range();
    } else {
        const cv::Vec2d b0(v.contact.x, v.contact.y), b1 = c + t + s * (b0 - c);
        v.contact = {b1[0], b1[1]};
        v.width *= s;
    }

    // The measurement set: followed points that move with the vehicle, and new corners.
    std::vector<cv::Vec2d> Z;
    for (size_t i : idx) {
        const cv::Vec2d p(prev[i].x, prev[i].y), z(cur[i].x, cur[i].y);
        const cv::Vec2d r = z - (c + t + s * (p - c));
        if (r.dot(r) <= p_.outlier_px * p_.outlier_px) Z.push_back(z);
    }
    if ((frame_ + v.id) % p_.birth_every_n == 0) {
        std::vector<cv::Vec2d> existing = means_of(v.phd);
        existing.insert(existing.end(), Z.begin(), Z.end());
        const std::vector<cv::Vec2d> fresh = box_corners(gray, v.box(), existing, p_.features);
        std::vector<cv::Vec2d> tags;
        for (const cv::Vec2d &f : fresh) tags.push_back(tag_of(f, v.contact, horizon));
        v.phd.add_births(fresh, tags);
        Z.insert(Z.end(), fresh.begin(), fresh.end());
    }
    v.phd.update(Z);
    v.phd.merge_and_prune();

    cv::Point2d cp;
    v.stable = 0;
    for (const GmComponent &g : v.phd.components()) v.stable += g.w >= p_.phd.stable_weight;
    double depth = 0.0;
    if (contact_from_features(v, horizon, cp, depth)) {
        // a row error e of a feature is e / k in the contact's depth: fewer features, or features higher on the
        // vehicle, measure the contact less well
        const double widen = p_.contact_full_depth > 0.0 ? std::sqrt(std::max(1.0, p_.contact_full_depth / depth)) : 1.0;
        v.ukf->update(cp, p_.contact_sigma_px * widen, horizon);
        v.contact = cp;
    }
}

void PhdTracker::follow_features(std::vector<Vehicle> &vs, const cv::Mat &gray, double horizon, double dt) {
    std::vector<cv::Point2f> prev, cur;
    std::vector<size_t> start;
    for (const Vehicle &v : vs) {
        start.push_back(prev.size());
        for (const GmComponent &g : v.phd.components()) prev.emplace_back(float(g.m[0]), float(g.m[1]));
    }
    start.push_back(prev.size());
    std::vector<uchar> ok;
    flow_.track(prev, cur, ok);
    if (cur.size() != prev.size()) {  // first frame: nothing followed
        cur = prev;
        ok.assign(prev.size(), 0);
    }
    for (size_t k = 0; k < vs.size(); ++k) {
        const auto a = long(start[k]), b = long(start[k + 1]);
        measure(vs[k], {prev.begin() + a, prev.begin() + b}, {cur.begin() + a, cur.begin() + b},
                {ok.begin() + a, ok.begin() + b}, gray, horizon, dt);
    }
}

bool PhdTracker::start_vehicle(const cv::Mat &gray, const Hypothesis &d, double horizon) {
    const cv::Point2d contact(d.box.x + 0.5 * d.box.width, d.box.y + d.box.height);
    if (!road_point(cam_, contact.x, contact.y, horizon).valid()) return false;
    Vehicle v(next_id_, GmPhd(p_.phd, uint32_t(next_id_)));
    v.ukf = std::make_unique<VehicleUkf>(p_.ukf, cam_, contact.x, contact.y, horizon);
    v.contact = contact;
    v.width = d.box.width;
    v.height.start(d, gray.cols, p_.height);
    v.confidence = d.score;
    // The first features: every corner is a birth (no draw) and measured once.
    const std::vector<cv::Vec2d> corners = box_corners(gray, d.box, {}, p_.features);
    for (const cv::Vec2d &f : corners) v.phd.add_birth(f, tag_of(f, contact, horizon));
    v.phd.update(corners);
    v.phd.merge_and_prune();
    v.confirmed = v.hits >= p_.confirm_hits;
    ++next_id_;
    vehicles_.push_back(std::move(v));
    return true;
}

bool PhdTracker::hidden(const Vehicle &v) const {
    const cv::Rect2f b = v.box();
    return std::any_of(vehicles_.begin(), vehicles_.end(), [&](const Vehicle &u) {
        return &u != &v && u.ukf->range() < v.ukf->range() && (u.box() & b).area() > p_.coast_max_hidden * b.area();
    });
}

std::vector<PhdTracker::VehicleAt> PhdTracker::vehicles_now() const {
    std::vector<VehicleAt> out;
    for (const Vehicle &v : vehicles_) out.push_back({v.id, v.box(), v.contact, v.width});
    return out;
}

void PhdTracker::use_detections(const FrameContext &ctx, const LaneModel &lanes, const std::vector<Hypothesis> &dets,
                                double horizon, const std::vector<VehicleAt> &then) {
    // Each vehicle's box on the detections' frame (as its features carried it there: the motion model), against
    // every detection; a vehicle the detections' frame did not have yet, with its box now.
    std::vector<const VehicleAt *> was(vehicles_.size(), nullptr);
    for (size_t i = 0; i < vehicles_.size(); ++i)
        for (const VehicleAt &a : then)
            if (a.id == vehicles_[i].id) was[i] = &a;
    // (a vehicle started below from these detections: its box now, which is the detection's)
    const auto box_then = [&](size_t i) { return i < was.size() && was[i] ? was[i]->box : vehicles_[i].box(); };
    cv::Mat_<float> iou(int(vehicles_.size()), int(dets.size()));
    std::vector<float> scores;
    for (const Hypothesis &d : dets) scores.push_back(d.score);
    for (size_t i = 0; i < vehicles_.size(); ++i) {
        const cv::Rect2f vb = box_then(i);
        for (size_t j = 0; j < dets.size(); ++j)
            iou(int(i), int(j)) = box_iou(vb, vehicles_[i].height.compared_box(dets[j], vb, p_.height));
        // A weak detection on a vehicle a nearer one hides is mostly the nearer one's edge: it keeps nothing alive.
        if (!p_.weak_keeps_hidden && hidden(vehicles_[i]))
            for (size_t j = 0; j < dets.size(); ++j)
                if (dets[j].score < p_.association.high_score) iou(int(i), int(j)) = 0.f;
    }
    const std::vector<int> pair = associate(iou, scores, p_.association);
    std::vector<bool> used(dets.size(), false);
    for (size_t k = 0; k < vehicles_.size(); ++k) {
        Vehicle &v = vehicles_[k];
        const int best = pair[k];
        if (best < 0) {
            v.detection_misses++;
            v.confidence *= 0.8f;
            continue;
        }
        used[size_t(best)] = true;
        Hypothesis d = dets[size_t(best)];
        if (was[k] && was[k]->width > 0.0) {
            // found frames ago: moved as the vehicle moved since (its contact point shifted, its box scaled)
            const double s = v.width / was[k]->width;
            const cv::Point2d dc(d.box.x + 0.5 * d.box.width, d.box.y + d.box.height);
            const cv::Point2d c = v.contact + s * (dc - was[k]->contact);
            const double w = s * d.box.width, h = s * d.box.height;
            d.box = cv::Rect2f(float(c.x - 0.5 * w), float(c.y - h), float(w), float(h));
            d.foot = {float(c.x), float(c.y)};
        }
        const cv::Point2d dc(d.box.x + 0.5 * d.box.width, d.box.y + d.box.height);
        // A contact row the vehicle's state cannot explain (past detection_gate_sigma) is a box that took in
        // something else: the detection confirms the vehicle but does not measure or re-anchor it.
        const double gate = p_.detection_gate_sigma;
        if (!(gate > 0.0 && v.ukf->contact_row_sigmas(dc, p_.detection_sigma_px, horizon) > gate)) {
            v.ukf->update(dc, p_.detection_sigma_px, horizon);
            // Re-anchor: the box and each feature's offset move towards the detected box.
            const double g = p_.anchor_gain;
            v.width = (1.0 - g) * v.width + g * d.box.width;
            v.contact = (1.0 - g) * v.contact + g * dc;
            v.height.take(d, ctx.gray.cols, g, p_.height);
            for (GmComponent &c : v.phd.components())
                c.tag = (1.0 - g) * c.tag + g * tag_of(c.m, dc, horizon);
        }
        v.hits++;
        v.detection_misses = 0;
        v.confirmed = v.confirmed || v.hits >= p_.confirm_hits;
        v.confidence = 0.7f * v.confidence + 0.3f * d.score;
    }
    std::vector<cv::Rect2f> tracked;  // each vehicle's box on the detections' frame, and those started from them
    for (size_t k = 0; k < vehicles_.size(); ++k) tracked.push_back(box_then(k));
    BirthGateParams gate;
    gate.nearer_below = p_.nearer_below;
    for (size_t i = 0; i < dets.size(); ++i) {
        if (used[i] || dets[i].score < p_.association.high_score) continue;  // a weak detection starts nothing
        const cv::Rect2f &b = dets[i].box;
        const cv::Point2f foot(b.x + 0.5f * b.width, b.y + b.height);
        // A vehicle beside the road (past birth_lanes_beside lanes of the ego lane, or of the ego path without lanes:
        // bushes, signs) starts no track.
        if (!on_road_ahead(lanes, cam_, ctx.ego, horizon, p_.road.lane_width_m, foot.x, foot.y,
                           p_.birth_lanes_beside))
            continue;
        // A learned detection scoring under birth_min_appearance may follow a vehicle but not found one: the
        // verifier's low-probability groups are mostly not vehicles (docs/detection.md), and each would become a track.
        // Its score is the verifier's probability, raised where a cue (a shadow edge) confirmed it
        // (detect/fuse_hypotheses.hpp).
        const bool doubted = std::isfinite(dets[i].appearance) && dets[i].score < p_.birth_min_appearance;
        if (!doubted && !on_tracked_vehicle(b, tracked, gate) && start_vehicle(ctx.gray, dets[i], horizon))
            tracked.push_back(vehicles_.back().box());
    }
}

// share of a vehicle's box inside a nearer vehicle's for it to be hidden (nearer_below)
constexpr double kHiddenInside = 0.9;

void PhdTracker::prune(const FrameContext &ctx, double horizon) {
    std::vector<TrackRank> ranks;
    std::vector<cv::Rect2f> boxes;
    for (const Vehicle &v : vehicles_) {
        ranks.push_back({v.id, v.hits});
        boxes.push_back(v.box());
    }
    std::vector<bool> gone = overlapping_tracks(ranks, boxes, p_.duplicate_iou);
    // A vehicle (almost) inside the box of a confirmed vehicle standing well below it, which the detector found at
    // its last run, is behind that one and hidden: what it still measures there is the nearer vehicle (a track
    // started from a box the image's side cut short). A nearer box the detector no longer confirms may be a vehicle
    // that left the view, its features spreading over what is behind it.
    if (p_.nearer_below > 0.0)
        for (size_t i = 0; i < boxes.size(); ++i)
            for (size_t j = 0; j < boxes.size() && !gone[i]; ++j) {
                const cv::Rect2f &b = boxes[i], &u = boxes[j];
                gone[i] = j != i && !gone[j] && vehicles_[j].confirmed && vehicles_[j].detection_misses == 0 &&
                          (u.y + u.height) - (b.y + b.height) > p_.nearer_below * b.height &&
                          (u & b).area() >= kHiddenInside * b.area();
            }
    // Eq. 12: a vehicle whose features are all lost ends, or first coasts (coast_frames, counted in `coast`): only
    // one the detector has found often and at its last run, and that no nearer vehicle hides (being hidden explains
    // the lost features). One that may not coast is put past its allowance, so it ends below.
    for (Vehicle &v : vehicles_) {
        const bool lost = v.age > 1 && v.phd.weight_in(cv::Rect2d(v.box())) < p_.end_weight;
        if (!lost) {
            v.coast = 0;
            continue;
        }
        const bool found_often = v.coast > 0 || (v.hits >= p_.coast_min_hits && v.detection_misses == 0);
        v.coast = found_often && !hidden(v) ? v.coast + 1 : p_.coast_frames + 1;
    }
    const MissLimits limits{p_.max_detection_misses, 1};
    for (size_t i = 0; i < vehicles_.size(); ++i) {
        const Vehicle &v = vehicles_[i];
        const double h = v.height.aspect * v.width;
        const bool ended = v.coast > (v.confirmed ? p_.coast_frames : 0);  // eq. 12, after coasting
        gone[i] = gone[i] || ended || missed_out(v.detection_misses, v.confirmed, limits) ||
                  out_of_view(cv::Rect2d(v.contact.x - 0.5 * v.width, v.contact.y - h, v.width, h), horizon,
                              ctx.gray.size()) ||
                  !(v.ukf->range() > 0.5);
    }
    erase_flagged(vehicles_, gone);
}

TrackState PhdTracker::report(const Vehicle &v) const {
    TrackState s;
    s.id = v.id;
    s.confirmed = v.confirmed;
    s.age_frames = v.age;
    s.box = v.box();
    s.confidence = std::clamp(v.confidence, 0.f, 1.f);
    s.range_m = float(v.ukf->range());
    s.range_sigma_m = float(v.ukf->range_sigma());
    s.lateral_m = float(v.ukf->lateral());
    // the estimate and its sigma: the geometry stage reports the rate once it has settled, and checks the
    // scale TTC against it before (track_kinematics.cpp)
    s.range_rate_mps = float(v.ukf->range_rate());
    s.range_rate_sigma_mps = float(v.ukf->range_rate_sigma());
    return s;
}

void PhdTracker::step(const FrameContext &ctx, DetectionStage &detectors, std::vector<TrackState> &tracks,
                      StageTimes &times, bool &full_detection) {
    CV_Assert(!ctx.gray.empty() && ctx.gray.type() == CV_8UC1);
    Stopwatch track_time;
    const double cpu0 = thread_cpu_ms();
    float detect_ms = 0.f;
    double detect_cpu_ms = 0.0;
    bool gap = false;
    const double dt = clock_.step(ctx.t_s, gap);
    if (gap) {
        vehicles_.clear();
        flow_.reset();
        pitch_.reset();
    }
    // Every n-th frame the detector parts: new vehicles, and re-anchoring of the tracked ones. With detect_lag L the
    // detection taken on frame k (a multiple of n) is that of frame k - L, started on the worker there, first thing
    // in the frame so that it has the rest of that frame's time too: the tracker takes detections on the same frames
    // as without the lag (a vehicle found on the first frame is confirmed on frame n either way).
    const int lag = detectors.can_start() ? std::min(p_.detect_lag, p_.detect_every_n - 1) : 0;
    const bool detect_now = frame_ % p_.detect_every_n == 0 && (lag == 0 || frame_ == 0);
    const bool lagged = lag > 0 && frame_ > 0 && (frame_ + lag) % p_.detect_every_n == 0;
    if (lagged) {
        detectors.start(ctx.road(), ctx.number);
        lagged_due_ = frame_ + lag;
        lagged_lanes_ = ctx.lanes;
    }
    const double lane_horizon = horizon_.update(ctx.lanes);
    flow_.next_frame(ctx.gray);
    // the car's pitch from the far scene, the slow part from the lanes (scene_pitch.hpp)
    std::vector<cv::Rect2f> boxes;
    for (const Vehicle &v : vehicles_) boxes.push_back(v.box());
    const double horizon = pitch_.update(ctx.gray, flow_, lane_horizon, boxes);
    for (Vehicle &v : vehicles_) {
        v.prev_range = v.ukf->range();
        v.ukf->predict(dt);
        v.age++;
    }
    follow_features(vehicles_, ctx.gray, horizon, dt);
    if (lagged) lagged_vehicles_ = vehicles_now();

    // A part that could not run (no road motion yet) counts as no detection: nothing is missed for it. The time
    // of the detection (or of the wait for the lagged one, "detect_wait") is the detector's; the fusion is tracking.
    full_detection = false;
    std::vector<Hypothesis> dets;
    const auto timed = [&](const auto &run) {
        Stopwatch sd;
        const double c0 = thread_cpu_ms();
        full_detection = run();
        detect_ms = sd.ms();
        detect_cpu_ms = thread_cpu_ms() - c0;
    };
    if (detect_now) {
        timed([&] { return detectors.detect(ctx.road(), dets, times); });
        if (full_detection) use_detections(ctx, ctx.lanes, dets, horizon, {});
    } else if (frame_ == lagged_due_) {
        timed([&] { return detectors.finish(dets, times); });
        lagged_due_ = -1;
        if (full_detection) use_detections(ctx, lagged_lanes_, dets, horizon, lagged_vehicles_);
    }
    ++frame_;
    prune(ctx, horizon);

    tracks.clear();
    for (const Vehicle &v : vehicles_) tracks.push_back(report(v));
    times.add("track", std::max(0.f, track_time.ms() - detect_ms));
    // the same work in CPU time of this thread (a loaded machine preempts the wall time; app/bench/phd.py)
    times.add("track_cpu", float(std::max(0.0, thread_cpu_ms() - cpu0 - detect_cpu_ms)));
}

namespace {

// The part, its configuration section and its factory (base/part_registry.hpp).
const bool registered = register_part<Tracker, PhdTrackerParams>(
    "phd", "phd", [](const PhdTrackerParams &p, const SectionLookup &c) {
        return std::make_unique<PhdTracker>(p, c.get<CameraParams>("camera"),
                                            HorizonTracker(c.get<HorizonParams>("horizon"), c.get<CameraParams>("camera")));
    });
// Its units' sections, held in its struct.
const bool units_registered = register_subsection("gmphd", "phd", &PhdTrackerParams::phd) &&
                              register_subsection("phd_features", "phd", &PhdTrackerParams::features) &&
                              register_subsection("phd_ukf", "phd", &PhdTrackerParams::ukf) &&
                              register_subsection("phd_pitch", "phd", &PhdTrackerParams::pitch);

} // namespace

} // namespace hw
