#include "track/phd/scene_pitch.hpp"

#include <opencv2/imgproc.hpp>

#include <algorithm>
#include <cmath>

namespace hw {

void ScenePitchParams::bind(ParamMap &m) {
    m.add("enabled", enabled,
          "follow the car's pitch by the far scene's vertical motion around the horizon (corners outside the "
          "vehicles); false = the lane horizon alone (docs/decisions.md)");
    m.add("band_above_px", band_above_px, 0.0, 500.0,
          "px; rows above the horizon searched for far corners (trees, bridges, buildings); the car's forward "
          "motion moves a point (v - v_h) V dt / Z rows, little for far points near the horizon");
    m.add("band_below_px", band_below_px, 0.0, 500.0,
          "px; rows below the horizon searched (the road there is far away: Z = fy h / (v - v_h))");
    m.add("max_points", max_points, 1, 1000, "corners followed per frame in the band (the strongest)");
    m.add("min_points", min_points, 1, 1000,
          "corners followed at least for a scene measurement; fewer (bare sky and road): the lane horizon");
    m.add("lane_gain", lane_gain, 0.0, 1.0,
          "1/frame; gain of the complementary filter towards the lane horizon: the slow part of the horizon "
          "from the lanes, the fast part from the scene (docs/tracking.md)");
    m.add("max_offset_px", max_offset_px, 0.0, 500.0,
          "px; the scene-followed horizon stays within this of the lane horizon (a bad frame cannot wreck range)");
}

namespace {

double median_of(std::vector<double> v) {
    const auto mid = v.begin() + long(v.size() / 2);
    std::nth_element(v.begin(), mid, v.end());
    return *mid;
}

} // namespace

// The pitch shift: the intercept at the horizon row of the line dy = p + e r through the points' vertical
// shifts dy against their rows r below the horizon (the car's forward motion adds e r, e = V dt / Z, zero at
// the horizon for any depth). Least squares, then again on the points within 3 MADs of that line (points on
// unboxed vehicles, LK slips). Too little spread of rows: the median shift.
double ScenePitch::pitch_shift(const std::vector<double> &dy, const std::vector<double> &r) const {
    std::vector<bool> use(dy.size(), true);
    double p = median_of(dy), e = 0.0;
    for (int pass = 0; pass < 2; ++pass) {
        double n = 0, sr = 0, sd = 0, srr = 0, srd = 0;
        for (size_t i = 0; i < dy.size(); ++i)
            if (use[i]) { n += 1; sr += r[i]; sd += dy[i]; srr += r[i] * r[i]; srd += r[i] * dy[i]; }
        const double var = srr - sr * sr / std::max(1.0, n);
        if (n < p_.min_points || var < n * 4.0) return p;  // rows within ~2 px of one another: no slope
        e = (srd - sr * sd / n) / var;
        p = (sd - e * sr) / n;
        std::vector<double> res;
        for (size_t i = 0; i < dy.size(); ++i) res.push_back(std::abs(dy[i] - p - e * r[i]));
        const double gate = 3.0 * std::max(0.05, 1.4826 * median_of(res));
        for (size_t i = 0; i < dy.size(); ++i) use[i] = res[i] <= gate;
    }
    return p;
}

double ScenePitch::update(const cv::Mat &gray, const PointFlow &flow, double lane_horizon,
                          const std::vector<cv::Rect2f> &boxes) {
    double dy = NAN;
    followed_ = 0;
    if (started_ && !prev_pts_.empty() && flow.ready()) {
        std::vector<cv::Point2f> cur;
        std::vector<uchar> ok;
        flow.track(prev_pts_, cur, ok);
        std::vector<double> d, r;  // vertical shift, row below the horizon
        for (size_t i = 0; i < cur.size(); ++i)
            if (ok[i]) {
                d.push_back(double(cur[i].y - prev_pts_[i].y));
                r.push_back(double(prev_pts_[i].y) - row_);
            }
        followed_ = int(d.size());
        if (followed_ >= p_.min_points) dy = pitch_shift(d, r);
    }
    if (!p_.enabled || !started_ || !std::isfinite(dy)) {
        row_ = lane_horizon;
    } else {
        const double predicted = row_ + dy;
        row_ = std::clamp(predicted + p_.lane_gain * (lane_horizon - predicted), lane_horizon - p_.max_offset_px,
                          lane_horizon + p_.max_offset_px);
    }
    started_ = true;

    // Corners for the next frame: the band around the horizon, the vehicles' boxes (grown by a LK window) left out.
    prev_pts_.clear();
    if (!p_.enabled) return row_;
    const cv::Rect band = cv::Rect(cv::Point(0, int(std::floor(row_ - p_.band_above_px))),
                                   cv::Point(gray.cols, int(std::ceil(row_ + p_.band_below_px)) + 1)) &
                          cv::Rect(0, 0, gray.cols, gray.rows);
    if (band.width < 8 || band.height < 8) return row_;
    cv::Mat mask(band.size(), CV_8U, cv::Scalar(255));
    const float grow = float(lk_.lk_window_px);
    for (const cv::Rect2f &b : boxes) {
        const cv::Rect r = cv::Rect(cv::Point(int(std::floor(b.x - grow)) - band.x, int(std::floor(b.y - grow)) - band.y),
                                    cv::Point(int(std::ceil(b.x + b.width + grow)) - band.x,
                                              int(std::ceil(b.y + b.height + grow)) - band.y)) &
                           cv::Rect(0, 0, band.width, band.height);
        if (r.area() > 0) mask(r).setTo(0);
    }
    // FAST corners, strongest first, at least 8 px apart (the minimum-eigenvalue search cost 0.19 ms on the band,
    // FAST 0.03 ms; docs/PERFORMANCE.md)
    for (const cv::Point2f &f : fast_corners_strongest_first(gray(band), lk_.fast_threshold)) {
        if (int(prev_pts_.size()) >= p_.max_points) break;
        if (!mask.at<uchar>(cv::Point(f))) continue;
        const cv::Point2f q(f.x + float(band.x), f.y + float(band.y));
        bool near = false;
        for (const cv::Point2f &e : prev_pts_) near = near || (q - e).dot(q - e) < 64.0f;
        if (!near) prev_pts_.push_back(q);
    }
    return row_;
}

} // namespace hw
