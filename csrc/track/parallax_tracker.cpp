#include "track/parallax_tracker.hpp"

#include "core/stopwatch.hpp"
#include "detect/photometric.hpp"
#include "geometry/road_motion_fit.hpp"
#include "lanes/lane_assembly.hpp"

#include <opencv2/imgproc.hpp>

#include <algorithm>
#include <cmath>

namespace hw {

namespace {

// The travel s in [0, s_max] whose flat-road homography G(s) best aligns the previous road band with
// the current one (mean |difference| over the lower half of the band, at the given pyramid level).
double search_travel(const cv::Mat &cur_level, const cv::Mat &prev_level, int band_top, int level,
                     const CameraParams &cam, double s_max, int steps) {
    const double f = 1.0 / (1 << level);
    const cv::Matx33d S(f, 0, 0, 0, f, -f * band_top, 0, 0, 1);
    const cv::Rect lower(0, cur_level.rows / 2, cur_level.cols, cur_level.rows - cur_level.rows / 2);
    double best = NAN, best_err = 1e300;
    cv::Mat warped, diff;
    for (int i = 0; i < steps; ++i) {
        const double s = s_max * i / (steps - 1);
        cv::warpPerspective(prev_level, warped, S * travel_homography(cam, s) * S.inv(), cur_level.size(),
                            cv::INTER_LINEAR, cv::BORDER_REPLICATE);
        cv::absdiff(cur_level(lower), warped(lower), diff);
        const double err = cv::mean(diff)[0];
        if (err < best_err) { best_err = err; best = s; }
    }
    return best;
}

// The road polygon continued toward the vanishing point up to row y_far: the lane model's area ends
// where its markings are still measured (60-80 m), but vehicles farther ahead stand on the same road.
// Its top edge (the two topmost neighbouring vertices) is replaced by the cut of the lines from the
// vanishing point through them at y_far.
std::vector<cv::Point> extend_road(const std::vector<cv::Point> &poly, cv::Point2f vp, float y_far) {
    if (poly.size() < 3 || !std::isfinite(vp.x) || !std::isfinite(y_far)) return poly;
    int y_top = poly[0].y;
    for (const auto &q : poly) y_top = std::min(y_top, q.y);
    if (!(y_far < float(y_top) - 1.f) || !(float(y_top) > vp.y + 1.f)) return poly;
    const size_t n = poly.size();
    for (size_t i = 0; i < n; ++i) {
        const cv::Point a = poly[i], b = poly[(i + 1) % n];
        if (a.y > y_top + 1 || b.y > y_top + 1 || a.x == b.x) continue;
        auto cut = [&](cv::Point q) {
            const float t = (y_far - vp.y) / (float(q.y) - vp.y);
            return cv::Point(cvRound(vp.x + t * (float(q.x) - vp.x)), cvRound(y_far));
        };
        std::vector<cv::Point> out(poly.begin(), poly.begin() + long(i) + 1);
        out.push_back(cut(a));
        out.push_back(cut(b));
        out.insert(out.end(), poly.begin() + long(i) + 1, poly.end());
        return out;
    }
    return poly;
}

// The lane model's road area widened to the ego lane +- `lanes` lane widths each side (the ego lane's width
// measured at each row), where that is wider; the lane model's area alone when the ego lane is not known.
std::vector<cv::Point> widen_road(const LaneModel &m, double lanes, cv::Size size) {
    if (!(lanes > 0.0) || !m.ego_left.valid || !m.ego_right.valid) return m.road_polygon;
    const float yb = float(size.height - 1);
    int yt_i = size.height - 1;
    for (const auto &q : m.road_polygon) yt_i = std::min(yt_i, q.y);
    const float yt = m.road_polygon.size() >= 3 ? float(yt_i) : std::max(m.ego_left.top.y, m.ego_right.top.y);
    if (!(yt < yb)) return m.road_polygon;
    auto span = [&](float y) {
        const float l = m.ego_left.x_at(y), r = m.ego_right.x_at(y), w = float(lanes) * (r - l);
        return std::pair<float, float>(l - w, r + w);
    };
    const auto b = span(yb), t = span(yt);
    if (!std::isfinite(b.first + b.second + t.first + t.second) || !(b.second > b.first)) return m.road_polygon;
    // Union with the lane model's area, row by row at the two ends (both are quadrilaterals meeting toward
    // the vanishing point, so the wider one at both ends is the wider one between).
    float ml_b = b.first, mr_b = b.second, ml_t = t.first, mr_t = t.second;
    for (const auto &q : m.road_polygon) {
        if (q.y >= yb - 1) { ml_b = std::min(ml_b, float(q.x)); mr_b = std::max(mr_b, float(q.x)); }
        if (q.y <= yt + 1) { ml_t = std::min(ml_t, float(q.x)); mr_t = std::max(mr_t, float(q.x)); }
    }
    return clip_to_image({{ml_b, yb}, {ml_t, yt}, {mr_t, yt}, {mr_b, yb}}, size);
}

} // namespace

void HomographyParams::bind(ParamMap &m) {
    dlt.bind(m);
    kalman.bind(m);
    m.add("road_model", road_model,
          "the measured homography is the one of a camera rotating a little (pitch, yaw, roll) and moving along and "
          "across the flat road of the camera model (five parameters, road_motion_fit.hpp), fitted to the "
          "correspondences the DLT kept; false: the DLT itself (eight parameters, as the paper), which extrapolates "
          "freely where the markings give no features");
}

void ParallaxTrackerParams::bind(ParamMap &m) {
    detect.bind(m);
    m.add("band_above_horizon", band_above_horizon, 0.0, 1.0,
          "share of the image height above the horizon kept in the road band (the rows features and differences "
          "are taken from); the band holds the roofs of near vehicles, the sky above is of no use");
    m.add("road_range_m", road_range_m, 0.0, 1000.0,
          "m; the lane model's road area is continued toward the vanishing point up to this range for the detector "
          "(the lanes stage ends it where markings are measured, 60 m: on TME tme08 the vehicles ahead at 60-75 m "
          "stood just beyond it and were never measured); 0 keeps the lane model's area");
    m.add("road_lanes_each_side", road_lanes_each_side, 0.0, 4.0,
          "lane widths; the detector's road area reaches at least this far beyond the ego lane's boundaries (the "
          "ego lane's width at each row), where the lane model's area is narrower: it covers the ego and adjacent "
          "lanes only, and an adjacent boundary found on a car's side or a gore area cut it further (Udacity "
          "test_small1, test_video: the cars one and two lanes to the right were outside it and never measured); "
          "2 scans as far as the thesis preset's detector (test_small2's car: 77 of 100 frames tracked, 0 without); "
          "it also takes in what stands beside the road, and road the homography extrapolates to (synthetic suite, "
          "particle seeds 1/2/3: MOTA 0.583/0.566/0.541 against 0.586/0.575/0.597 with 0, precision 0.83-0.87 "
          "against 0.87-0.88; overpass_shadow 0.37-0.54 against 0.60-0.63); 0 keeps the lane model's area");
    m.add("hood_frac", hood_frac, 0.0, 0.5,
          "share of the image height at the bottom taken by the car's own bonnet: it moves with the camera, not "
          "with the road, so it gives no features and no differences; 0 for none");
    m.add("exclude_vehicle_corners", exclude_vehicle_corners,
          "corners inside the boxes of confirmed vehicles are not used for the homography: they are not on the road");
    m.add("search_max_speed_mps", search_max_speed_mps, 1.0, 100.0,
          "m/s; without a prediction the travel since the previous frame is searched up to this speed");
    m.add("search_steps", search_steps, 2, 1000, "travels tried in that search (0 .. max speed * dt)");
    m.add("long_gap", long_gap, 0, 10,
          "frames; besides the previous frame, the frame is compared with the one this many frames back "
          "(homographies chained) and its regions are added where the short difference has none: a vehicle "
          "keeping its distance 50 m ahead shows ~0.3 px of parallax per frame at 30 fps, long_gap times more "
          "here (the paper ran at 5-10 fps); 0 or 1 disables (saves one warp per frame)");
    m.add("long_gap_min_range_m", long_gap_min_range_m, 0.0, 1000.0,
          "m; the long-gap difference covers only the road beyond this range (the band's upper rows), 0 = the whole "
          "band; 20 saves ~0.8 ms per 640x480 frame but cost 0.06 MOTA on the synthetic suite (0.27 against 0.34), "
          "10 cost 0.02, so 0 by default");
    m.add("max_dt_s", max_dt_s, 0.001, 100.0,
          "s; a longer gap between frames (or time going back) starts the homography and the tracks again");
}

RoadMotion ParallaxTracker::road_motion() const {
    RoadMotion r;
    if (!h_step_.valid) return r;
    r.state = h_step_.status == HomographyKalman::Status::kAccepted ? RoadMotion::State::kAccepted
                                                                     : RoadMotion::State::kPredicted;
    r.coast_frames = h_step_.coast_frames;
    r.H = h_step_.H;
    return r;
}

ParallaxTracker::ParallaxTracker(const LaneFeatureParams &features, const HomographyParams &homography,
                                 const ParallaxTrackerParams &parallax, const ParticleParams &particles,
                                 const CameraParams &cam)
    : fp_(features), hp_(homography), pp_(parallax), cam_(cam), kf_(homography.kalman, cam), pf_(particles, cam) {
    band_top_ = std::clamp(int(std::floor(cam.horizon_row() - pp_.band_above_horizon * cam.height)), 0,
                           std::max(0, cam.height - 16));
}

void ParallaxTracker::reset() {
    kf_.reset();
    pf_.reset();
    prev_.release();
    cur_.release();
    prev_level_.release();
    history_.clear();
    started_ = false;
    h_step_ = HomographyStep{};
    detection_ = ParallaxFrame{};
    last_tracks_.clear();
}

void ParallaxTracker::step(const FrameContext &ctx, std::vector<TrackState> &tracks, StageTimes &times,
                           bool &full_detection) {
    const cv::Mat &gray = ctx.gray;
    CV_Assert(gray.type() == CV_8UC1 && gray.cols == cam_.width && gray.rows == cam_.height);
    double dt = started_ ? ctx.t_s - last_t_s_ : 0.0;
    if (started_ && (dt > pp_.max_dt_s || dt < 0.0)) {
        reset();
        dt = 0.0;
    }
    started_ = true;
    last_t_s_ = ctx.t_s;
    full_detection = false;
    h_step_ = HomographyStep{};
    detection_ = ParallaxFrame{};

    // The road's vanishing point: the lane model's, else the camera's horizon and yaw.
    cv::Point2f vp = ctx.lanes.vanishing_point;
    if (!std::isfinite(vp.x) || !std::isfinite(vp.y))
        vp = {float(cam_.cx - cam_.fx * std::tan(cam_.yaw_deg * M_PI / 180.0)), float(cam_.horizon_row())};
    prev_ = cur_;
    cur_ = gray.clone();
    // This frame's road band at the detector's level (the search below and the detector use it).
    cv::Mat level = cur_.rowRange(band_top_, cur_.rows);
    for (int l = 0; l < pp_.detect.level; ++l) {
        cv::Mat down;
        cv::pyrDown(level, down);
        level = down;
    }
    if (level.data == cur_.data) level = level.clone();  // level 0: keep the band even when cur_ changes
    const bool have_prev_level = !prev_level_.empty() && prev_level_.size() == level.size();

    // features + homography
    {
        Stopwatch sw;
        const double speed = ctx.ego.speed_mps;
        kf_.predict(std::isfinite(speed) && dt > 0.0 ? speed * dt : NAN);
        if (!kf_.has_prediction() && have_prev_level && dt > 0.0)
            kf_.guess_travel(search_travel(level, prev_level_, band_top_, pp_.detect.level, cam_,
                                           pp_.search_max_speed_mps * dt, pp_.search_steps));
        LaneFeatures f;
        // A searched travel only starts the features (large patches); the DLT then relies on RANSAC.
        const bool predicted = kf_.has_prediction() && !kf_.guessed();
        if (!prev_.empty()) f = lane_correspondences(cur_, prev_, vp, cam_, kf_.predicted_px(), predicted, fp_);
        f.matches.erase(std::remove_if(f.matches.begin(), f.matches.end(),
                                       [&](const Correspondence &c) { return c.cur.y >= float(hood_row()); }),
                        f.matches.end());
        if (pp_.exclude_vehicle_corners) {
            // Where the confirmed vehicles are now (last estimate moved by its velocity), widened a little
            // (a hypothesis is not yet a reason to give up road features).
            std::vector<cv::Rect2f> boxes;
            for (const auto &t : last_tracks_) {
                if (!t.confirmed) continue;
                cv::Rect2f b = t.box;
                if (std::isfinite(t.vel_px_s.x)) b += cv::Point2f(float(t.vel_px_s.x * dt), float(t.vel_px_s.y * dt));
                boxes.push_back(cv::Rect2f(b.x - 0.1f * b.width, b.y - 0.1f * b.height, 1.2f * b.width, 1.2f * b.height));
            }
            f.matches.erase(std::remove_if(f.matches.begin(), f.matches.end(),
                                           [&](const Correspondence &c) {
                                               for (const auto &b : boxes)
                                                   if (b.contains(c.cur)) return true;
                                               return false;
                                           }),
                            f.matches.end());
        }
        times.add("features", sw.ms());
        Stopwatch sh;
        std::vector<cv::Point2f> from, to;
        for (const auto &c : f.matches) {
            from.push_back(c.prev);
            to.push_back(c.cur);
        }
        const cv::Matx33d pred = kf_.predicted_px();
        HomographyFit fit = fit_homography(from, to, hp_.dlt, predicted ? &pred : nullptr);
        if (fit.ok && hp_.road_model) {
            const RoadMotionFit rm = fit_road_motion(from, to, fit.H, cam_, hp_.dlt);
            if (rm.ok) {
                fit.H = rm.H;
                fit.used = rm.used;
                fit.rms_px = rm.rms_px;
            }
        }
        h_step_.status = prev_.empty() ? HomographyKalman::Status::kNone : kf_.update(fit.ok ? &fit.H : nullptr);
        h_step_.valid = kf_.valid();
        h_step_.coast_frames = kf_.coast_frames();
        h_step_.correspondences = int(f.matches.size());
        h_step_.used = fit.ok ? fit.used : 0;
        h_step_.distance = kf_.last_distance();
        h_step_.H = kf_.H_px();
        times.add("homography", sh.ms());
    }

    // parallax detection on the aligned road band
    std::vector<PointMeasurement> z;
    {
        Stopwatch sw;
        // Differences against the previous frame and, for vehicles keeping their distance (a fraction of
        // a pixel of parallax per frame when far), against the frame long_gap frames back, through the
        // chained homographies H_k H_{k-1} ... of the bands kept in history_ (newest last).
        if (kf_.valid() && have_prev_level) {
            // The bonnet is no road: the road area stops above it.
            LaneModel road = ctx.lanes;
            road.road_polygon = widen_road(ctx.lanes, pp_.road_lanes_each_side, cur_.size());
            if (hood_row() < cam_.height) {
                if (road.road_polygon.empty())
                    road.road_polygon = {{0, band_top_}, {cam_.width - 1, band_top_}, {cam_.width - 1, cam_.height - 1},
                                         {0, cam_.height - 1}};
                for (auto &q : road.road_polygon) q.y = std::min(q.y, hood_row() - 1);
            }
            if (pp_.road_range_m > 0.0)
                road.road_polygon = extend_road(road.road_polygon, vp,
                                                float(vp.y + cam_.fy * cam_.height_m / pp_.road_range_m));
            const cv::Matx33d H_now = kf_.H_px();
            cv::Mat grad_cells;  // the current band's gradient cells, shared by both differences
            detection_ = detect_parallax(level, prev_level_, cur_, band_top_, H_now, road, vp, cam_, pp_.detect, &grad_cells);
            full_detection = true;
            for (const auto &m : detection_.measurements) z.push_back({m.point, m.box, m.sad});
            if (pp_.long_gap > 1 && int(history_.size()) >= pp_.long_gap - 1) {
                cv::Matx33d H = H_now;
                cv::Mat old_level;
                for (int i = 0; i < pp_.long_gap - 1; ++i) {
                    const auto &e = history_[history_.size() - 1 - size_t(i)];
                    H = H * e.second;
                    old_level = e.first;
                }
                // Only the far road (beyond long_gap_min_range_m, the upper rows of the band): near vehicles
                // show parallax enough against the previous frame, and the rows below cost most of the work.
                int rows = level.rows;
                if (pp_.long_gap_min_range_m > 0.0) {
                    const int cell_h = std::max(1, pp_.detect.cell_h_px >> pp_.detect.level);
                    const double y_cut = vp.y + cam_.fy * cam_.height_m / pp_.long_gap_min_range_m;
                    const int r = int((y_cut - band_top_) / double(1 << pp_.detect.level)) / cell_h * cell_h;
                    rows = std::clamp(r, std::min(level.rows, 4 * cell_h), level.rows);
                }
                const ParallaxFrame far = detect_parallax(level.rowRange(0, rows), old_level.rowRange(0, rows), cur_, band_top_,
                                                          H, road, vp, cam_, pp_.detect,
                                                          rows == level.rows ? &grad_cells : nullptr);
                // A long-gap region is used where the short gap saw nothing (the near, fast vehicles are
                // measured sharper against the previous frame).
                for (const auto &m : far.measurements) {
                    bool seen = false;
                    for (const auto &n : detection_.measurements) seen = seen || (m.box & n.box).area() > 0.f;
                    if (!seen) {
                        z.push_back({m.point, m.box, m.sad});
                        detection_.measurements.push_back(m);
                    }
                }
            }
        }
        // Keep the bands of the last long_gap - 1 frames before this one with the homography to the next.
        if (pp_.long_gap > 1 && have_prev_level && kf_.valid()) {
            history_.emplace_back(prev_level_, h_step_.H);
            while (int(history_.size()) > pp_.long_gap - 1) history_.pop_front();
        } else {
            history_.clear();
        }
        prev_level_ = level;
        times.add("parallax", sw.ms());
    }

    // joint particle filter
    {
        Stopwatch sw;
        pf_.step(dt, z, gray.size(), vp);
        const size_t first = tracks.size();
        pf_.report(tracks);
        last_tracks_.assign(tracks.begin() + long(first), tracks.end());
        times.add("particles", sw.ms());
    }
}

ParallaxTracker::RoadResidual ParallaxTracker::road_residual(const LaneModel &lanes) const {
    if (prev_.empty() || !h_step_.valid) return {};
    cv::Mat warped;
    cv::warpPerspective(prev_, warped, h_step_.H, cur_.size(), cv::INTER_LINEAR, cv::BORDER_CONSTANT, cv::Scalar(0));
    cv::Mat valid;
    cv::warpPerspective(cv::Mat(prev_.size(), CV_8UC1, cv::Scalar(255)), valid, h_step_.H, cur_.size(), cv::INTER_NEAREST,
                        cv::BORDER_CONSTANT, cv::Scalar(0));
    // The ego lane up to 40 m (mostly plain road: the rest of the road area holds more vehicles and, where
    // a lane was extrapolated, the verge and guardrail); the road area when the ego lane is not known.
    cv::Mat road = cv::Mat::zeros(cur_.size(), CV_8UC1);
    const float y_far = float(lanes.vanishing_point.y + cam_.fy * cam_.height_m / 40.0);
    if (lanes.valid && std::isfinite(y_far) && y_far < float(cur_.rows - 1)) {
        const float y_near = float(cur_.rows - 1);
        const std::vector<cv::Point> lane{
            cv::Point(cvRound(lanes.ego_left.x_at(y_far)), cvRound(y_far)), cv::Point(cvRound(lanes.ego_right.x_at(y_far)), cvRound(y_far)),
            cv::Point(cvRound(lanes.ego_right.x_at(y_near)), cvRound(y_near)), cv::Point(cvRound(lanes.ego_left.x_at(y_near)), cvRound(y_near))};
        cv::fillConvexPoly(road, lane, cv::Scalar(255));
    } else if (lanes.road_polygon.size() >= 3) {
        cv::fillPoly(road, std::vector<std::vector<cv::Point>>{lanes.road_polygon}, cv::Scalar(255));
    } else {
        road.rowRange(std::clamp(int(cam_.horizon_row()) + 1, 0, road.rows), road.rows).setTo(255);
    }
    for (const auto &m : detection_.measurements) {
        const cv::Rect b(cv::Point(int(m.box.x) - 4, int(m.box.y) - 4), cv::Point(int(m.box.br().x) + 4, int(m.box.br().y) + 4));
        road(b & cv::Rect(0, 0, road.cols, road.rows)).setTo(0);
    }
    road.rowRange(hood_row(), road.rows).setTo(0);
    road &= valid;
    RoadResidual out;
    const int n = cv::countNonZero(road);
    if (n == 0) return out;
    // Both differences with the smooth brightness change between the two images taken out (as the detector
    // does, photometric.hpp), and the aligned one also as it is.
    cv::Mat d_al, d_un;
    cv::subtract(cur_, warped, d_al, cv::noArray(), CV_16S);
    cv::subtract(cur_, prev_, d_un, cv::noArray(), CV_16S);
    const int cell = std::max(4, cur_.cols / 64);
    const double trim = pp_.detect.photometric_trim;
    out.aligned = float(compensated_mean(d_al, fit_brightness_surface(d_al, road, cell, cell, trim), road));
    out.unaligned = float(compensated_mean(d_un, fit_brightness_surface(d_un, road, cell, cell, trim), road));
    out.aligned_raw = float(compensated_mean(d_al, BrightnessSurface{}, road));
    return out;
}

} // namespace hw
