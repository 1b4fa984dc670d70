#include "detect/parallax/part.hpp"

#include "base/part_registry.hpp"
#include "base/stopwatch.hpp"
#include "lanes/lane_assembly.hpp"

#include <algorithm>
#include <cmath>

namespace hw {

namespace {

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

void ParallaxSection::bind(ParamMap &m) {
    detect.bind(m);
    m.add("band_above_horizon", band_above_horizon, 0.0, 1.0,
          "share of the image height above the horizon kept in the road band (the rows features and differences "
          "are taken from); the band holds the roofs of near vehicles, the sky above is of no use");
    m.add("road_range_m", road_range_m, 0.0, 1000.0,
          "m; the lane model's road area is continued toward the vanishing point up to this range for the "
          "detector; 0 keeps the lane model's area (docs/tracking.md)");
    m.add("road_lanes_each_side", road_lanes_each_side, 0.0, 4.0,
          "lane widths; the detector's road area reaches at least this far beyond the ego lane's boundaries "
          "where the lane model's area is narrower; 0 = the lane model's area (docs/tracking.md)");
    m.add("exclude_vehicle_corners", exclude_vehicle_corners,
          "corners inside the boxes of confirmed vehicles are not used for the homography: they are not on the road");
    m.add("search_max_speed_mps", search_max_speed_mps, 1.0, 100.0,
          "m/s; without a prediction the travel since the previous frame is searched up to this speed");
    m.add("search_steps", search_steps, 2, 1000, "travels tried in that search (0 .. max speed * dt)");
    m.add("long_gap", long_gap, 0, 10,
          "frames; the frame is also compared with the one this many frames back and those regions added where "
          "the short difference has none (far vehicles at 30 fps; docs/tracking.md)");
    m.add("long_gap_min_range_m", long_gap_min_range_m, 0.0, 1000.0,
          "m; the long-gap difference covers only the road beyond this range (the band's upper rows), 0 = the whole "
          "band; 20 saves ~0.8 ms per 640x480 frame but cost 0.06 MOTA on the synthetic suite (0.27 against 0.34), "
          "10 cost 0.02, so 0 by default");
    m.add("max_dt_s", max_dt_s, 0.001, 100.0,
          "s; a longer gap between frames (or time going back) starts the homography and the tracks again");
}

void ParallaxDifferenceDetector::reset() {
    history_.clear();
    last_ = ParallaxFrame{};
}

bool ParallaxDifferenceDetector::detect(const RoadContext &ctx, std::vector<Hypothesis> &out, StageTimes &times) {
    last_ = ParallaxFrame{};
    Stopwatch sw;
    const RoadMotionFrame *rm = ctx.motion;
    if (!rm || !rm->valid() || rm->prev_band.empty()) {
        times.add("parallax", sw.ms());
        return false;
    }
    const cv::Mat &level = rm->band, &prev_level = rm->prev_band;
    const cv::Point2f vp = rm->vp;
    const int band_top = rm->band_top;
    // Differences against the previous frame and, for vehicles keeping their distance (a fraction of
    // a pixel of parallax per frame when far), against the frame long_gap frames back, through the
    // chained homographies H_k H_{k-1} ... of the bands kept in history_ (newest last).
    // The bonnet is no road: the road area stops above it.
    LaneModel road = ctx.lanes;
    road.road_polygon = widen_road(ctx.lanes, p_.road_lanes_each_side, ctx.gray.size());
    if (rm->hood_row < cam_.height) {
        if (road.road_polygon.empty())
            road.road_polygon = {{0, band_top}, {cam_.width - 1, band_top}, {cam_.width - 1, cam_.height - 1},
                                 {0, cam_.height - 1}};
        for (auto &q : road.road_polygon) q.y = std::min(q.y, rm->hood_row - 1);
    }
    if (p_.road_range_m > 0.0)
        road.road_polygon = extend_road(road.road_polygon, vp, float(vp.y + cam_.fy * cam_.height_m / p_.road_range_m));
    const cv::Matx33d H_now = rm->motion.H;
    cv::Mat grad_cells;  // the current band's gradient cells, shared by both differences
    last_ = detect_parallax(level, prev_level, ctx.gray, band_top, H_now, road, vp, cam_, p_.detect, &grad_cells);
    if (p_.long_gap > 1 && int(history_.size()) >= p_.long_gap - 1) {
        cv::Matx33d H = H_now;
        cv::Mat old_level;
        for (int i = 0; i < p_.long_gap - 1; ++i) {
            const auto &e = history_[history_.size() - 1 - size_t(i)];
            H = H * e.second;
            old_level = e.first;
        }
        // Only the far road (beyond long_gap_min_range_m, the upper rows of the band): near vehicles
        // show parallax enough against the previous frame, and the rows below cost most of the work.
        int rows = level.rows;
        if (p_.long_gap_min_range_m > 0.0) {
            const int cell_h = std::max(1, p_.detect.cell_h_px >> p_.detect.level);
            const double y_cut = vp.y + cam_.fy * cam_.height_m / p_.long_gap_min_range_m;
            const int r = int((y_cut - band_top) / double(1 << p_.detect.level)) / cell_h * cell_h;
            rows = std::clamp(r, std::min(level.rows, 4 * cell_h), level.rows);
        }
        const ParallaxFrame far = detect_parallax(level.rowRange(0, rows), old_level.rowRange(0, rows), ctx.gray, band_top,
                                                  H, road, vp, cam_, p_.detect, rows == level.rows ? &grad_cells : nullptr);
        // A long-gap region is used where the short gap saw nothing (the near, fast vehicles are
        // measured sharper against the previous frame).
        for (const auto &m : far.measurements) {
            bool seen = false;
            for (const auto &n : last_.measurements) seen = seen || (m.box & n.box).area() > 0.f;
            if (!seen) last_.measurements.push_back(m);
        }
    }
    for (const auto &m : last_.measurements) {
        Hypothesis h;
        h.box = m.box;
        h.foot = m.point;
        h.score = std::min(1.f, m.sad / 64.f);
        h.strength = m.sad;
        h.source = "parallax";
        out.push_back(h);
    }
    times.add("parallax", sw.ms());
    return true;
}

void ParallaxDifferenceDetector::end_frame(const RoadContext &ctx) {
    // Keep the bands of the last long_gap - 1 frames before this one with the homography to the next.
    const RoadMotionFrame *rm = ctx.motion;
    if (p_.long_gap > 1 && rm && rm->valid() && !rm->prev_band.empty()) {
        history_.emplace_back(rm->prev_band, rm->motion.H);
        while (int(history_.size()) > p_.long_gap - 1) history_.pop_front();
    } else {
        history_.clear();
    }
}

namespace {

// The part, its configuration section and its factory (base/part_registry.hpp).
const bool registered = register_part<Detector, ParallaxSection>(
    "parallax", "parallax",
    [](const ParallaxSection &p, const SectionLookup &c) {
        return std::make_unique<ParallaxDifferenceDetector>(p, c.get<CameraParams>("camera"));
    },
    /*needs_road_motion=*/true);

} // namespace

} // namespace hw
