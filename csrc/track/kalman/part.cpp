#include "track/kalman/part.hpp"

#include "base/part_registry.hpp"
#include "base/stopwatch.hpp"
#include "cues/road_prior.hpp"
#include "track/association.hpp"
#include "track/duplicate_pruning.hpp"
#include "track/track_deletion.hpp"

#include <algorithm>
#include <cmath>

namespace hw {

void KalmanBoxParams::bind(ParamMap &m) {
    m.add("detect_every_n", detect_every_n, 1, 1000,
          "frames; the detection stage runs on every n-th frame, the frames between only search around the "
          "predictions (thesis: 10; 3 measured best, docs/decisions.md)");
    m.add("accel_mps2", accel_mps2, 0.0, 50.0,
          "m/s^2; bound A of a vehicle's acceleration relative to the ego, converted to px/s^2 with the "
          "vehicle's image width; sets the Kalman process noise (bounded-acceleration model)");
    m.add("ego_accel_px_s2", ego_accel_px_s2, 0.0, 1e5,
          "px/s^2; image acceleration any vehicle can show from the ego's pitch and yaw motion "
          "(road bumps), added to the bound A whatever the range");
    m.add("p_max", p_max, 0.0, 0.5,
          "probability that the acceleration is exactly +-A in the bounded-acceleration model, "
          "sigma^2 = A^2/3 (1 + 4 p_max - p_zero)");
    m.add("p_zero", p_zero, 0.0, 1.0, "probability of zero acceleration in that model");
    m.add("meas_sigma_px", meas_sigma_px, 0.05, 50.0,
          "px; 1-sigma error of a measured corner (edge peaks are sub-pixel), floor");
    m.add("meas_sigma_frac", meas_sigma_frac, 0.0, 1.0,
          "vehicle widths; measured-corner error of large (near) vehicles, whose edges are blurred wider");
    m.add("init_speed_mps", init_speed_mps, 0.01, 50.0,
          "m/s; 1-sigma image speed of a new track (converted with its width); a new vehicle's "
          "motion is unknown until its second measurement");
    m.add("gate_sigma", gate_sigma, 0.5, 10.0,
          "innovation standard deviations; half-size of the ROI searched around a prediction (the "
          "Kalman filter decides how far to look)");
    m.add("min_gate_px", min_gate_px, 0.0, 100.0, "px; smallest half-size of that search window");
    m.add("side_change_floor_px", side_change_floor_px, 0.0, 100.0,
          "px; the two-threshold side rule falls back to the largest projection when a side moves "
          "more than the largest change seen so far, but never less than this");
    m.add("bottom_min_frac", roi.bottom_min_frac, 0.0, 1.0,
          "fraction of the shadow step threshold; the bottom-edge profile of a tracked vehicle must "
          "reach this (e.g. half of its columns with a full shadow step)");
    m.add("max_scale_change", roi.max_scale_change, 0.01, 1.0,
          "fraction; a re-found vehicle's width may differ from the predicted one by at most this");
    m.add("confirm_hits", confirm_hits, 1, 100,
          "M; measurements before a track is confirmed (reported as confirmed, used for warnings)");
    m.add("max_misses", max_misses, 1, 1000,
          "K; consecutive frames a confirmed vehicle may be missed (edges, detection and correlation "
          "all failed) before it is deleted");
    m.add("tentative_max_misses", tentative_max_misses, 1, 100,
          "frames; a tentative track missed this many times in a row is deleted");
    m.add("ncc_min", ncc_min, -1.0, 1.0,
          "normalised correlation of the last box with the region now above which an unfound "
          "vehicle is kept (thesis' check before dropping a vehicle)");
    m.add("ncc_template_px", ncc_template_px, 4, 256,
          "px; templates are scaled down to at most this width, bounding the cost of the check");
    m.add("ncc_min_std_gray", ncc_min_std_gray, 0.0, 100.0,
          "gray levels; a template flatter than this is not used (it correlates with any flat road)");
    m.add("ncc_search_frac", ncc_search_frac, 0.0, 1.0,
          "vehicle widths; the correlation looks for the vehicle this far around its prediction");
    m.add("ncc_sigma_scale", ncc_sigma_scale, 1.0, 100.0,
          "factor; a position found by correlation is used as a measurement this much noisier than "
          "an edge measurement");
    m.add("max_coast_frames", max_coast_frames, 0, 1000,
          "frames; how long a vehicle may be kept by correlation alone before misses count again");
    m.add("match_iou", match_iou, 0.0, 1.0,
          "IoU of a detection with a predicted box above which it measures that vehicle");
    m.add("duplicate_iou", duplicate_iou, 0.0, 1.0,
          "IoU above which two tracks are the same vehicle; the one with fewer measurements goes");
    m.add("beside_overlap", beside_overlap, 0.0, 1.0,
          "share of the narrower width; a new detection on a tracked vehicle's bottom row (beside_bottom_tol) "
          "overlapping its columns this much starts no track (docs/tracking.md)");
    m.add("beside_bottom_tol", beside_bottom_tol, 0.0, 1.0,
          "vehicle widths (the narrower); bottom rows at most this far apart are one range for beside_overlap");
    m.add("min_width_ratio", min_width_ratio, 0.0, 1.0,
          "expected vehicle widths at its bottom row; a track narrower than this has lost its vehicle "
          "(squeezed between a neighbour's edges) and is deleted");
    m.add("max_width_ratio", max_width_ratio, 1.0, 10.0,
          "expected vehicle widths; a track wider than this is deleted");
    m.add("max_width_depth_change", max_width_depth_change, 0.0, 100.0,
          "|measured width / depth below the horizon, against the vehicle's at its detections, - 1| at most for "
          "an ROI or template measurement; 100 = off (docs/tracking.md)");
    m.add("max_dt_s", max_dt_s, 0.01, 100.0,
          "s; a gap between frames longer than this drops all tracks (the predictions are void)");
}

KalmanTracker::KalmanTracker(const KalmanBoxParams &k, const RoiSearch &roi)
    : kalman_(k), roi_(roi), clock_(k.max_dt_s) {}

void KalmanTracker::reset() {
    tracks_.clear();
    next_id_ = 1;
    frames_since_detection_ = 0;
    clock_.reset();
}

namespace {

// Quality of a measurement for the confidence: 0.5 when the weaker side just passes, towards 1.
float side_quality(float side_excess) { return 1.f - 0.5f / std::sqrt(std::max(1.f, side_excess)); }

} // namespace

cv::Rect2f KalmanTracker::box_of(const KalmanBox::Vec3 &z, double aspect) const {
    const float w = float(z[2] - z[0]), h = float(aspect * w);
    return {float(z[0]), float(z[1]) - h, w, h};
}

// The height is not tracked by the filter: each detection of the vehicle refines its aspect ratio (a truck's only
// by measured tops: track/vehicle_height.hpp), and its width per depth below the horizon (keeps_width_per_depth).
void KalmanTracker::take_shape(Track &t, const Hypothesis &d) const {
    t.height.take(d, cols_, 0.4, kalman_.height);
    note_width_per_depth(t, d.box);
}

// A detection's width per depth below the horizon: the first sets the vehicle's, later ones blend in (0.4 each).
void KalmanTracker::note_width_per_depth(Track &t, const cv::Rect2f &b) const {
    const double depth = b.y + b.height - horizon_;
    if (depth <= 1.0) return;
    const double wpd = b.width / depth;
    t.width_per_depth = t.width_per_depth > 0.0 ? 0.6 * t.width_per_depth + 0.4 * wpd : wpd;
}

KalmanBox::Vec3 KalmanTracker::sigma_of(const Track &t) const {
    const KalmanBox::Vec3 z = t.kf.measurement();
    const double s = std::max(kalman_.meas_sigma_px, kalman_.meas_sigma_frac * (z[2] - z[0]));
    return {s, s, s};
}

double KalmanTracker::accel_bound(const Track &t) const {
    // A vehicle of width W m at range Z spans w = fx W / Z px: a lateral acceleration a shows as
    // fx a / Z = a w / W px/s^2.
    const KalmanBox::Vec3 z = t.kf.measurement();
    return kalman_.accel_mps2 * std::max(0.0, z[2] - z[0]) / roi_.vehicle_width_m() + kalman_.ego_accel_px_s2;
}

void KalmanTracker::predict_all(double dt, const cv::Point2f &vp) {
    for (Track &t : tracks_) {
        const double a = accel_bound(t);
        t.kf.predict(dt, a, a, kalman_.p_max, kalman_.p_zero, perspective_accel(t, vp));
        t.age++;
        t.updated = false;
    }
}

// A vehicle moving at constant velocity relative to the ego does not move at constant velocity in
// the image: with scale rate s = (dw/dt) / w = -(dZ/dt) / Z, every point's offset from the vanishing
// point scales as 1/Z, so its image acceleration is
//     d^2/dt^2 (x - x_vp) = 2 (x - x_vp) s^2,   d^2/dt^2 (y - y_h) = 2 (y - y_h) s^2.
// Negligible far away; near a closing vehicle it dominates (0.5 s before contact at 20 m/s closing,
// a few thousand px/s^2), and the constant-velocity prediction would lag out of its own gate.
KalmanBox::Vec3 KalmanTracker::perspective_accel(const Track &t, const cv::Point2f &vp) const {
    const KalmanBox::Vec6 &x = t.kf.state();
    const double w = x[2] - x[0];
    // Only from a scale rate that measurements keep honest: a coasting track would drift on it.
    if (t.misses > 0 || t.coast > 0 || t.hits < kalman_.confirm_hits) return KalmanBox::Vec3::Zero();
    if (!(w > 1.0) || !std::isfinite(vp.x) || !std::isfinite(vp.y)) return KalmanBox::Vec3::Zero();
    const double s = (x[5] - x[3]) / w;
    return 2.0 * s * s * KalmanBox::Vec3(x[0] - vp.x, x[1] - vp.y, x[2] - vp.x);
}

void KalmanTracker::apply(Track &t, const KalmanBox::Vec3 &z, float sigma_scale, float quality) {
    const KalmanBox::Vec3 s = sigma_of(t);
    t.kf.update(z, s[0] * sigma_scale, s[1] * sigma_scale);
    t.confidence = 0.7f * t.confidence + 0.3f * quality;
}

bool KalmanTracker::measure_by_roi(const cv::Mat &gray, Track &t) {
    const KalmanBox::Vec3 z = t.kf.measurement(), s = sigma_of(t);
    const KalmanBox::Mat3 S = t.kf.innovation_cov(s[0], s[1]);
    RoiPrediction pred;
    pred.x1 = float(z[0]); pred.y1 = float(z[1]); pred.x2 = float(z[2]);
    pred.sigma_x = float(std::sqrt(std::max(S(0, 0), S(2, 2))));
    pred.gate_x = float(std::max(kalman_.min_gate_px, kalman_.gate_sigma * pred.sigma_x));
    pred.gate_y = float(std::max(kalman_.min_gate_px, kalman_.gate_sigma * std::sqrt(S(1, 1))));
    pred.max_side_change = std::clamp(t.max_side_change, float(kalman_.side_change_floor_px),
                                      std::max(float(kalman_.side_change_floor_px), pred.gate_x));
    const RoiMeasurement m = roi_.search(gray, pred, kalman_.roi);
    if (!m.found) return false;
    // On a flat road a vehicle's width and its bottom's depth below the horizon grow together (w = W d / h): a side
    // that jumped to another edge changes their ratio, approaching or not.
    if (!keeps_width_per_depth(t, m.x1, m.y1, m.x2)) return false;
    t.max_side_change = std::max({t.max_side_change, std::abs(m.x1 - pred.x1), std::abs(m.x2 - pred.x2)});
    apply(t, KalmanBox::Vec3(m.x1, m.y1, m.x2), 1.f, side_quality(m.side_excess));
    return true;
}

bool KalmanTracker::measure_by_detection(Track &t, std::vector<Hypothesis> &dets, std::vector<bool> &used) {
    const cv::Rect2f pred = box_of(t);
    std::vector<float> iou(dets.size());
    for (size_t i = 0; i < dets.size(); ++i) iou[i] = box_iou(pred, t.height.compared_box(dets[i], pred, kalman_.height));
    const int best = take_best_unused(iou, used, float(kalman_.match_iou));
    if (best < 0) return false;
    take_shape(t, dets[size_t(best)]);
    const cv::Rect2f &b = dets[size_t(best)].box;
    apply(t, KalmanBox::Vec3(b.x, b.y + b.height, b.x + b.width), 1.f, dets[size_t(best)].score);
    return true;
}

// Whether a measured box (x1, x2 at bottom row y) keeps the width per depth below the horizon the vehicle's
// detections gave (blended as its aspect, 0.4 each); without one (no detection below the horizon yet) it does.
bool KalmanTracker::keeps_width_per_depth(const Track &t, double x1, double y, double x2) const {
    const double depth = y - horizon_;
    if (!(t.width_per_depth > 0.0) || depth <= 1.0) return true;
    return std::abs((x2 - x1) / depth / t.width_per_depth - 1.0) <= kalman_.max_width_depth_change;
}

bool KalmanTracker::measure_by_template(const cv::Mat &gray, Track &t) {
    if (!t.appearance.usable()) return false;
    // Move the template's box with the predicted motion of the bottom-left corner since it was cut.
    const KalmanBox::Vec3 z = t.kf.measurement();
    const cv::Rect2f last = box_of(t.appearance_z, t.height.aspect);
    const float dx = float(z[0]) - last.x, dy = float(z[1]) - (last.y + last.height);
    const cv::Rect2f at(t.appearance.box.x + dx, t.appearance.box.y + dy, t.appearance.box.width,
                        t.appearance.box.height);
    const TemplateMatch m = match_template(gray, t.appearance, at, float(kalman_.ncc_search_frac * (z[2] - z[0])));
    if (m.ncc < kalman_.ncc_min) return false;
    // The template keeps its width: sliding down the image with the road's texture, it is no vehicle.
    if (!keeps_width_per_depth(t, z[0] + m.shift.x, z[1] + m.shift.y, z[2] + m.shift.x)) return false;
    apply(t, KalmanBox::Vec3(z[0] + m.shift.x, z[1] + m.shift.y, z[2] + m.shift.x), float(kalman_.ncc_sigma_scale),
          0.5f * m.ncc);
    return true;
}

// Hidden behind a nearer vehicle (a track standing lower in the image, measured this frame) that
// covers most of its box: its template would be compared with the occluder, so it is not used.
bool KalmanTracker::occluded(const Track &t) const {
    const cv::Rect2f b = box_of(t);
    for (const Track &o : tracks_) {
        if (&o == &t || !o.updated) continue;
        const cv::Rect2f ob = box_of(o);
        if (ob.y + ob.height > b.y + b.height && (ob & b).area() >= 0.5f * b.area()) return true;
    }
    return false;
}

BirthGateParams KalmanTracker::birth_gate() const {
    BirthGateParams g;
    g.beside_overlap = kalman_.beside_overlap;
    g.beside_bottom_tol = kalman_.beside_bottom_tol;
    return g;
}

void KalmanTracker::start_tracks(const cv::Mat &gray, const std::vector<Hypothesis> &dets,
                                 const std::vector<bool> &used) {
    const BirthGateParams gate = birth_gate();
    std::vector<cv::Rect2f> tracked;
    for (const Track &t : tracks_) tracked.push_back(box_of(t));
    for (size_t i = 0; i < dets.size(); ++i) {
        if (used[i]) continue;
        const cv::Rect2f &b = dets[i].box;
        if (on_tracked_vehicle(b, tracked, gate)) continue;
        const KalmanBox::Vec3 z(b.x, b.y + b.height, b.x + b.width);
        const double w = b.width;
        Track t(next_id_++, KalmanBox(z, std::max(kalman_.meas_sigma_px, kalman_.meas_sigma_frac * w),
                                      kalman_.init_speed_mps * w / roi_.vehicle_width_m()));
        t.confidence = dets[i].score;
        t.height.start(dets[i], gray.cols, kalman_.height);
        note_width_per_depth(t, b);
        t.appearance = make_template(gray, b, kalman_.ncc_template_px, kalman_.ncc_min_std_gray);
        t.appearance_z = z;
        t.updated = true;
        t.confirmed = t.hits >= kalman_.confirm_hits;
        tracked.push_back(box_of(t));
        tracks_.push_back(std::move(t));
    }
}

void KalmanTracker::prune(const FrameContext &ctx) {
    const cv::Mat &gray = ctx.gray;
    std::vector<TrackRank> ranks;
    std::vector<cv::Rect2f> boxes;
    for (const Track &t : tracks_) {
        ranks.push_back({t.id, t.hits});
        boxes.push_back(box_of(t));
    }
    std::vector<bool> gone = overlapping_tracks(ranks, boxes, kalman_.duplicate_iou);
    const MissLimits limits{kalman_.max_misses, kalman_.tentative_max_misses};
    for (size_t i = 0; i < tracks_.size(); ++i) {
        const Track &t = tracks_[i];
        const KalmanBox::Vec3 z = t.kf.measurement();
        const double w = z[2] - z[0], h = t.height.aspect * w;
        // A box that shrank or grew far from any vehicle at its row lost its vehicle.
        const float w_exp = roi_.expected_width(float(z[1]), gray.size(), ctx.lanes, ctx.camera);
        const bool implausible = w_exp > 0.f && (w < kalman_.min_width_ratio * w_exp || w > kalman_.max_width_ratio * w_exp);
        gone[i] = gone[i] || implausible || missed_out(t.misses, t.confirmed, limits) ||
                  out_of_view(cv::Rect2d(z[0], z[1] - h, w, h), horizon_, gray.size());
    }
    erase_flagged(tracks_, gone);
}

TrackState KalmanTracker::report(const Track &t) const {
    TrackState s;
    const KalmanBox::Vec6 &x = t.kf.state();
    s.id = t.id;
    s.confirmed = t.confirmed;
    s.age_frames = t.age;
    s.box = box_of(t);
    s.confidence = std::clamp(t.confidence, 0.f, 1.f);
    s.vel_px_s = cv::Point2f(float(0.5 * (x[3] + x[5])), float(x[4]));  // bottom centre
    s.bottom_sigma_px = float(std::sqrt(t.kf.cov()(1, 1)));
    return s;
}

void KalmanTracker::step(const FrameContext &ctx, DetectionStage &detectors, std::vector<TrackState> &tracks,
                        StageTimes &times, bool &full_detection) {
    CV_Assert(!ctx.gray.empty() && ctx.gray.type() == CV_8UC1);
    Stopwatch track_time;
    float detect_ms = 0.f;
    bool gap = false;
    const double dt = clock_.step(ctx.t_s, gap);
    if (gap) {  // the predictions mean nothing any more
        tracks_.clear();
        frames_since_detection_ = 0;
    }
    cols_ = ctx.gray.cols;

    // Predict, then re-find each vehicle in the ROI around its prediction.
    predict_all(dt, vanishing_point(ctx.gray.size(), ctx.lanes, ctx.camera));
    horizon_ = horizon_row(ctx.gray.size(), ctx.lanes, ctx.camera);
    for (Track &t : tracks_) t.updated = measure_by_roi(ctx.gray, t);

    // Every n-th frame: the full detector, for vehicles the ROI search lost and for new ones.
    const bool detect_now = frames_since_detection_ % kalman_.detect_every_n == 0;
    std::vector<Hypothesis> dets;
    std::vector<bool> used;
    full_detection = false;
    if (detect_now) {
        Stopwatch sd;
        full_detection = detectors.detect(ctx.road(), dets, times);
        detect_ms = sd.ms();
        used.assign(dets.size(), false);
        for (Track &t : tracks_) {
            if (!t.updated) {
                t.updated = measure_by_detection(t, dets, used);
                continue;
            }
            const cv::Rect2f tb = box_of(t);
            for (size_t i = 0; i < dets.size(); ++i)
                if (!used[i] && box_iou(tb, t.height.compared_box(dets[i], tb, kalman_.height)) >= kalman_.match_iou) {
                    used[i] = true;
                    take_shape(t, dets[i]);
                }
        }
    }
    frames_since_detection_ = detect_now ? 1 : frames_since_detection_ + 1;

    // Bookkeeping: hits and misses; the correlation check before a confirmed vehicle is missed.
    for (Track &t : tracks_) {
        if (t.updated) {
            t.hits++;
            t.misses = 0;
            t.coast = 0;
            t.confirmed = t.confirmed || t.hits >= kalman_.confirm_hits;
            t.appearance = make_template(ctx.gray, box_of(t), kalman_.ncc_template_px,
                                         kalman_.ncc_min_std_gray);
            t.appearance_z = t.kf.measurement();
        } else if (t.confirmed && !occluded(t) && measure_by_template(ctx.gray, t)) {
            if (++t.coast > kalman_.max_coast_frames) t.misses++;
        } else {
            t.misses++;
            t.confidence *= 0.7f;
        }
    }
    if (full_detection) start_tracks(ctx.gray, dets, used);
    prune(ctx);

    tracks.clear();
    for (const Track &t : tracks_) tracks.push_back(report(t));
    times.add("track", std::max(0.f, track_time.ms() - detect_ms));
}

namespace {

// The part, its configuration section and its factory (base/part_registry.hpp). The ROI search takes shared units'
// sections (shadow_edge, verify) and the pipeline's, none of a detector part's: it runs with any detectors.
const bool registered = register_part<Tracker, KalmanBoxParams>(
    "kalman", "kalman", [](const KalmanBoxParams &p, const SectionLookup &c) {
        RoadPriorParams prior;
        prior.share(c);
        return std::make_unique<KalmanTracker>(
            p, RoiSearch(c.get<ShadowEdgeParams>("shadow_edge"), c.get<VerifyParams>("verify"), prior));
    });

} // namespace

} // namespace hw
