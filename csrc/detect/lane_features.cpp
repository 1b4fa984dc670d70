#include "detect/lane_features.hpp"

#include <opencv2/imgproc.hpp>
#include <opencv2/video/tracking.hpp>

#include <algorithm>
#include <cmath>
#include <numeric>

namespace hw {

void LaneFeatureParams::bind(ParamMap &m) {
    m.add("marking_width_m", marking_width_m, 0.05, 1.0,
          "m; painted line width the row filter is sized for (0.10-0.15 m on motorways)");
    m.add("t_factor", t_factor, 0.5, 5.0,
          "marking widths; the filter's neighbour distance t(j); 1.5 lets both neighbours of any pixel "
          "on a marking fall off it, also for markings slanted by perspective");
    m.add("t_min_px", t_min_px, 1, 50, "px; smallest t, near the vanishing point where markings are 1-2 px wide");
    m.add("response_min", response_min, 1.0, 510.0,
          "gray levels; eq. 1 response kept; the response is twice the margin over the brighter neighbour, so "
          "24 keeps markings 12 levels brighter than the road around them");
    m.add("max_range_m", max_range_m, 5.0, 500.0,
          "m; farthest road range filtered; beyond 50 m markings are too thin and too close to the horizon to "
          "constrain the homography (the paper names features near the horizon as unreliable)");
    m.add("hough_threshold", hough_threshold, 1, 1000, "votes; accumulator threshold of the probabilistic Hough transform");
    m.add("hough_min_length_px", hough_min_length_px, 2, 1000, "px; shortest Hough segment; a far dash is ~10 px long");
    m.add("hough_max_gap_px", hough_max_gap_px, 0, 100, "px; gap bridged inside one Hough segment");
    m.add("min_angle_deg", min_angle_deg, 0.0, 90.0,
          "deg from horizontal; flatter segments are vehicle bottoms or shadows; 12 still keeps the outer road "
          "edges of a three-lane road (about 14 deg at 640x480)");
    m.add("cluster_tol_px", cluster_tol_px, 0.5, 100.0,
          "px; a segment joins a marking when both its ends lie this close to the marking's line (plus one "
          "marking width at that row)");
    m.add("max_markings", max_markings, 1, 32, "count; markings kept, most Hough support first");
    m.add("grow_along", grow_along, 0.0, 10.0,
          "fraction of the marking's row span; its search region extends this much above and below the "
          "segments so the whole marking (the next dashes) is inside");
    m.add("grow_across", grow_across, 0.5, 20.0,
          "marking widths; half-width of the search region across the marking, enough for the dash corners and "
          "the mean segment's error");
    m.add("grow_min_px", grow_min_px, 1, 100, "px; smallest half-width of a search region (far rows)");
    m.add("max_corners", max_corners, 4, 5000, "count; Harris corners at most; bounds the Lucas-Kanade cost");
    m.add("harris_quality", harris_quality, 1e-4, 1.0,
          "fraction of the strongest Harris response a corner must reach");
    m.add("harris_k", harris_k, 0.01, 0.25, "Harris detector free parameter (det - k trace^2)");
    m.add("min_corner_distance_px", min_corner_distance_px, 1, 100, "px; corners closer than this are one");
    m.add("lk_window_px", lk_window_px, 5, 101, "px; Lucas-Kanade window side");
    m.add("lk_levels", lk_levels, 0, 6,
          "pyramid levels above the base; the predicted homography gives the start, so 3 covers what the "
          "prediction misses (shake, speed changes)");
    m.add("fb_max_px", fb_max_px, 0.05, 10.0,
          "px; largest forward-backward error of a kept correspondence; a point sliding along a marking or "
          "hidden by a vehicle does not come back");
}

cv::Range lane_feature_rows(int height, float horizon_row, const CameraParams &cam, const LaneFeatureParams &p) {
    // Row of range Z: y = y_h + fy h / Z.
    const int top = int(std::ceil(horizon_row + cam.fy * cam.height_m / p.max_range_m));
    const int y0 = std::clamp(top, 0, height);
    return cv::Range(y0, height);
}

void marking_response(const cv::Mat &gray, cv::Range rows, float horizon_row, const CameraParams &cam,
                      const LaneFeatureParams &p, cv::Mat &binary) {
    CV_Assert(gray.type() == CV_8UC1);
    binary.create(gray.size(), CV_8UC1);
    binary.setTo(0);
    const int W = gray.cols;
    const int thr = int(std::ceil(p.response_min));
    for (int j = rows.start; j < rows.end; ++j) {
        // Marking width in px at this row: fx / Z * w_m with Z = fy h / (j - y_h).
        const double px_per_m = std::max(0.0, cam.fx * (j - horizon_row) / (cam.fy * cam.height_m));
        const int t = std::max(p.t_min_px, int(std::lround(p.t_factor * p.marking_width_m * px_per_m)));
        if (2 * t >= W) continue;
        const uint8_t *x = gray.ptr<uint8_t>(j);
        uint8_t *y = binary.ptr<uint8_t>(j);
        for (int i = t; i < W - t; ++i) {
            const int l = x[i - t], r = x[i + t];
            // eq. 1: y_i = 2 x_i - (x_{i-t} + x_{i+t}) - |x_{i-t} - x_{i+t}|
            const int resp = 2 * x[i] - (l + r) - std::abs(l - r);
            y[i] = resp >= thr ? 255 : 0;
        }
    }
}

namespace {

// Distance of p from the infinite line through a and b.
float line_distance(cv::Point2f a, cv::Point2f b, cv::Point2f p) {
    const cv::Point2f d = b - a;
    const float n = std::hypot(d.x, d.y);
    return n < 1e-6f ? float(cv::norm(p - a)) : std::fabs(d.x * (p.y - a.y) - d.y * (p.x - a.x)) / n;
}

struct Segment {
    cv::Point2f lower, upper;
    float length;
};

} // namespace

std::vector<MarkingSegment> marking_segments(const cv::Mat &binary, cv::Range rows, float horizon_row,
                                             const CameraParams &cam, const LaneFeatureParams &p) {
    std::vector<MarkingSegment> out;
    if (rows.size() < 2) return out;
    std::vector<cv::Vec4i> lines;
    cv::HoughLinesP(binary.rowRange(rows), lines, 1.0, CV_PI / 180.0, p.hough_threshold, p.hough_min_length_px,
                    p.hough_max_gap_px);
    const float tan_min = float(std::tan(p.min_angle_deg * CV_PI / 180.0));
    std::vector<Segment> segs;
    for (const auto &l : lines) {
        cv::Point2f a(float(l[0]), float(l[1] + rows.start)), b(float(l[2]), float(l[3] + rows.start));
        if (std::fabs(b.y - a.y) < tan_min * std::fabs(b.x - a.x)) continue;  // too flat
        if (a.y < b.y) std::swap(a, b);
        segs.push_back({a, b, float(cv::norm(a - b))});
    }
    std::sort(segs.begin(), segs.end(), [](const Segment &a, const Segment &b) { return a.length > b.length; });

    // Marking width in px at row y (0 above the horizon).
    auto width_px = [&](float y) {
        return float(std::max(0.0, p.marking_width_m * cam.fx * (y - horizon_row) / (cam.fy * cam.height_m)));
    };
    struct Cluster {
        Segment seed;
        std::vector<int> members;
        float support = 0.f;
    };
    std::vector<Cluster> clusters;
    for (int s = 0; s < int(segs.size()); ++s) {
        const Segment &g = segs[s];
        bool joined = false;
        for (auto &c : clusters) {
            const float tl = float(p.cluster_tol_px) + width_px(g.lower.y);
            const float tu = float(p.cluster_tol_px) + width_px(g.upper.y);
            if (line_distance(c.seed.lower, c.seed.upper, g.lower) < tl &&
                line_distance(c.seed.lower, c.seed.upper, g.upper) < tu) {
                c.members.push_back(s);
                c.support += g.length;
                joined = true;
                break;
            }
        }
        if (!joined) clusters.push_back({g, {s}, g.length});
    }
    std::sort(clusters.begin(), clusters.end(), [](const Cluster &a, const Cluster &b) { return a.support > b.support; });
    if (int(clusters.size()) > p.max_markings) clusters.resize(size_t(p.max_markings));

    const float y_min = float(rows.start), y_max = float(rows.end - 1);
    for (const auto &c : clusters) {
        MarkingSegment m;
        // s_i = (1/S_i) sum_j (p_l_ij, p_u_ij): the mean segment of the marking.
        float top = 1e9f, bottom = -1e9f;
        for (int s : c.members) {
            m.lower += segs[s].lower;
            m.upper += segs[s].upper;
            top = std::min(top, segs[s].upper.y);
            bottom = std::max(bottom, segs[s].lower.y);
        }
        m.lower *= 1.f / float(c.members.size());
        m.upper *= 1.f / float(c.members.size());
        m.segments = int(c.members.size());
        // The region follows the mean segment's line x(y) = x_l + k (y - y_l) over the cluster's rows,
        // extended by grow_along of that span at both ends.
        const float dy = m.lower.y - m.upper.y;
        if (dy < 1.f) continue;
        const float k = (m.upper.x - m.lower.x) / (m.upper.y - m.lower.y);
        const float span = bottom - top;
        const float yt = std::max(y_min, top - float(p.grow_along) * span);
        const float yb = std::min(y_max, bottom + float(p.grow_along) * span);
        const float stretch = std::sqrt(1.f + k * k);  // horizontal width of a slanted band
        auto half = [&](float y) {
            return stretch * std::max(float(p.grow_min_px), float(p.grow_across) * width_px(y));
        };
        auto x_at = [&](float y) { return m.lower.x + k * (y - m.lower.y); };
        m.region = {cv::Point(cvRound(x_at(yt) - half(yt)), cvRound(yt)), cv::Point(cvRound(x_at(yt) + half(yt)), cvRound(yt)),
                    cv::Point(cvRound(x_at(yb) + half(yb)), cvRound(yb)), cv::Point(cvRound(x_at(yb) - half(yb)), cvRound(yb))};
        out.push_back(std::move(m));
    }
    return out;
}

void LaneFeatureTracker::process(const cv::Mat &gray, float horizon_row, const CameraParams &cam,
                                 const cv::Matx33d &H_guess, LaneFeatures &out) {
    CV_Assert(gray.type() == CV_8UC1 && !gray.empty());
    out = LaneFeatures{};
    const cv::Size win(p_.lk_window_px, p_.lk_window_px);
    std::vector<cv::Mat> pyr;
    // Own copies (tryReuseInputImage = false): the frame may be a view of the caller's buffer.
    cv::buildOpticalFlowPyramid(gray, pyr, win, p_.lk_levels, false, cv::BORDER_REFLECT_101, cv::BORDER_CONSTANT, false);
    if (!prev_pyr_.empty() && prev_pyr_[0].size() != gray.size()) prev_pyr_.clear();

    const cv::Range rows = lane_feature_rows(gray.rows, horizon_row, cam, p_);
    if (!prev_pyr_.empty() && rows.size() > 1) {
        marking_response(gray, rows, horizon_row, cam, p_, binary_);
        out.markings = marking_segments(binary_, rows, horizon_row, cam, p_);
        if (!out.markings.empty()) {
            // Harris corners inside the union of the search regions.
            cv::Mat mask = cv::Mat::zeros(gray.size(), CV_8UC1);
            cv::Rect box;
            for (const auto &m : out.markings) {
                cv::fillConvexPoly(mask, m.region, cv::Scalar(255));
                box |= cv::boundingRect(m.region);
            }
            box &= cv::Rect(0, rows.start, gray.cols, rows.size());
            if (box.width > 4 && box.height > 4) {
                cv::goodFeaturesToTrack(gray(box), out.corners, p_.max_corners, p_.harris_quality,
                                        p_.min_corner_distance_px, mask(box), 3, true, p_.harris_k);
                for (auto &c : out.corners) c += cv::Point2f(float(box.x), float(box.y));
            }
        }
        if (out.corners.size() >= 4) {
            // Start each corner where the predicted homography puts it in the previous frame.
            const cv::Matx33d Hinv = H_guess.inv();
            std::vector<cv::Point2f> prev_pts, back;
            cv::perspectiveTransform(out.corners, prev_pts, cv::Mat(Hinv));
            back = out.corners;
            std::vector<uint8_t> st_f, st_b;
            std::vector<float> err;
            const cv::TermCriteria crit(cv::TermCriteria::COUNT | cv::TermCriteria::EPS, 20, 0.03);
            cv::calcOpticalFlowPyrLK(pyr, prev_pyr_, out.corners, prev_pts, st_f, err, win, p_.lk_levels, crit,
                                     cv::OPTFLOW_USE_INITIAL_FLOW);
            cv::calcOpticalFlowPyrLK(prev_pyr_, pyr, prev_pts, back, st_b, err, win, p_.lk_levels, crit,
                                     cv::OPTFLOW_USE_INITIAL_FLOW);
            const float fb2 = float(p_.fb_max_px * p_.fb_max_px);
            const cv::Rect inside(0, 0, gray.cols, gray.rows);
            for (size_t i = 0; i < out.corners.size(); ++i) {
                const cv::Point2f d = back[i] - out.corners[i];
                if (st_f[i] && st_b[i] && d.dot(d) <= fb2 && inside.contains(cv::Point(prev_pts[i])))
                    out.matches.push_back({prev_pts[i], out.corners[i]});
            }
        }
    }
    prev_pyr_ = std::move(pyr);
}

} // namespace hw
