#include "road/road_motion_stage.hpp"

#include "base/stopwatch.hpp"
#include "detect/photometric.hpp"
#include "geometry/road_motion_fit.hpp"

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

} // namespace

void HomographyParams::bind(ParamMap &m) {
    dlt.bind(m);
    kalman.bind(m);
    m.add("road_model", road_model,
          "the measured homography is a camera rotating a little and moving over the flat road (five "
          "parameters) fitted to the DLT's inliers; false = the DLT itself, as the paper (docs/tracking.md)");
    m.add("fit_tilt", fit_tilt,
          "with road_model, fit the correspondences again with the road plane's tilt free (a sixth parameter): "
          "self-calibration's pitch and height from the road's motion (docs/calibration.md)");
    m.add("measure_residual", measure_residual,
          "report the road's alignment residual each frame (road_residual in the result; two full-frame warps, "
          "for evaluation)");
}

RoadMotionStage::RoadMotionStage(const LaneFeatureParams &features, const HomographyParams &homography,
                                 const ParallaxSection &parallax, const CameraParams &cam)
    : fp_(features), hp_(homography), pp_(parallax), cam_(cam), kf_(homography.kalman, cam) {
    band_top_ = std::clamp(int(std::floor(cam.horizon_row() - pp_.band_above_horizon * cam.height)), 0,
                           std::max(0, cam.height - 16));
}

void RoadMotionStage::reset() {
    kf_.reset();
    prev_.release();
    cur_.release();
    prev_level_.release();
    started_ = false;
    h_step_ = HomographyStep{};
    out_ = RoadMotionFrame{};
}

const RoadMotionFrame &RoadMotionStage::update(const cv::Mat &gray, double t_s, const LaneModel &lanes,
                                               const EgoMotion &ego, const std::vector<TrackState> &last_tracks,
                                               StageTimes &times) {
    CV_Assert(gray.type() == CV_8UC1 && gray.cols == cam_.width && gray.rows == cam_.height);
    double dt = started_ ? t_s - last_t_s_ : 0.0;
    const bool restart = started_ && (dt > pp_.max_dt_s || dt < 0.0);
    if (restart) {
        reset();
        dt = 0.0;
    }
    started_ = true;
    last_t_s_ = t_s;
    h_step_ = HomographyStep{};
    out_ = RoadMotionFrame{};

    const cv::Point2f vp = road_vanishing_point(lanes, cam_);
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

    Stopwatch sw;
    const double speed = ego.speed_mps;
    kf_.predict(std::isfinite(speed) && dt > 0.0 ? speed * dt : NAN);
    if (!kf_.has_prediction() && have_prev_level && dt > 0.0)
        kf_.guess_travel(search_travel(level, prev_level_, band_top_, pp_.detect.level, cam_,
                                       pp_.search_max_speed_mps * dt, pp_.search_steps));
    LaneFeatures f;
    // A searched travel only starts the features (large patches); the DLT then relies on RANSAC.
    const bool predicted = kf_.has_prediction() && !kf_.guessed();
    if (!prev_.empty()) f = lane_correspondences(cur_, prev_, vp, cam_, kf_.predicted_px(), predicted, fp_);
    const float hood = float(cam_.hood_row(cam_.height));
    f.matches.erase(std::remove_if(f.matches.begin(), f.matches.end(),
                                   [&](const Correspondence &c) { return c.cur.y >= hood; }),
                    f.matches.end());
    if (pp_.exclude_vehicle_corners && !restart) {
        // Where the confirmed vehicles are now (last estimate moved by its velocity), widened a little
        // (a hypothesis is not yet a reason to give up road features).
        std::vector<cv::Rect2f> boxes;
        for (const auto &t : last_tracks) {
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
    RoadMotionFit rm;
    if (fit.ok && hp_.road_model) {
        rm = fit_road_motion(from, to, fit.H, cam_, hp_.dlt, hp_.fit_tilt);
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

    if (h_step_.valid) {
        out_.motion.state = h_step_.status == HomographyKalman::Status::kAccepted ? RoadMotion::State::kAccepted
                                                                                 : RoadMotion::State::kPredicted;
        out_.motion.coast_frames = h_step_.coast_frames;
        out_.motion.H = h_step_.H;
        if (out_.motion.state == RoadMotion::State::kAccepted && rm.tilt_ok) {
            out_.motion.tilt_ok = true;
            out_.motion.tilt_rad = rm.tilt_rad;
            out_.motion.tilt_travel_m = rm.tilt_travel_m;
        }
    }
    out_.vp = vp;
    out_.band_top = band_top_;
    out_.level = pp_.detect.level;
    out_.band = level;
    if (have_prev_level) out_.prev_band = prev_level_;
    out_.hood_row = cam_.hood_row(cam_.height);
    prev_level_ = level;
    return out_;
}

RoadMotionStage::RoadResidual RoadMotionStage::road_residual(const LaneModel &lanes,
                                                             const std::vector<cv::Rect2f> &detections) const {
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
    for (const auto &box : detections) {
        const cv::Rect b(cv::Point(int(box.x) - 4, int(box.y) - 4), cv::Point(int(box.br().x) + 4, int(box.br().y) + 4));
        road(b & cv::Rect(0, 0, road.cols, road.rows)).setTo(0);
    }
    road.rowRange(cam_.hood_row(cam_.height), road.rows).setTo(0);
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
