#include "track/phd/box_features.hpp"

#include <opencv2/features2d.hpp>
#include <opencv2/imgproc.hpp>
#include <opencv2/video/tracking.hpp>

#include <algorithm>
#include <cmath>

namespace hw {

void BoxFeatureParams::bind(ParamMap &m) {
    m.add("detector", detector, "shi_tomasi|harris|fast",
          "corner detector for a vehicle's features: shi_tomasi (min eigenvalue), harris, or fast; compared in "
          "docs/tracking.md");
    m.add("max_per_vehicle", max_per_vehicle, 1, 500, "corners looked for in one box per search (the strongest)");
    m.add("quality", quality, 1e-4, 1.0,
          "fraction of the box's strongest corner response a Shi-Tomasi or Harris corner must reach");
    m.add("fast_threshold", fast_threshold, 1, 255, "gray levels; FAST's difference threshold on its circle");
    m.add("min_distance_px", min_distance_px, 0.0, 100.0,
          "px; corners closer than this to another corner or an existing feature are not taken");
    m.add("inner_margin_frac", inner_margin_frac, 0.0, 0.45,
          "box widths/heights; left out at each side and at the top (background shows there)");
    m.add("bottom_margin_frac", bottom_margin_frac, 0.0, 0.45,
          "box heights; left out at the bottom (the shadow and the road under the bumper move with the road)");
    m.add("lk_window_px", lk_window_px, 3, 63, "px; side of the Lucas-Kanade window");
    m.add("lk_levels", lk_levels, 0, 6, "pyramid levels above the full frame (each halves the size)");
    m.add("lk_iterations", lk_iterations, 1, 100, "Lucas-Kanade iterations per level at most");
    m.add("fb_max_px", fb_max_px, 0.01, 50.0,
          "px; a point tracked forward then backward must come back this close to its start, or it is lost");
    m.add("roi_margin_px", roi_margin_px, 4, 1000,
          "px; LK works on the pyramids of the points' bounding box grown by this much (the largest image motion "
          "of a vehicle between frames plus the window at the coarsest level); the rest of the frame is not read");
}

std::vector<cv::Point2f> fast_corners_strongest_first(const cv::Mat &gray, int threshold) {
    std::vector<cv::KeyPoint> kps;
    cv::FAST(gray, kps, threshold, true);
    std::sort(kps.begin(), kps.end(), [](const cv::KeyPoint &a, const cv::KeyPoint &b) { return a.response > b.response; });
    std::vector<cv::Point2f> pts;
    pts.reserve(kps.size());
    for (const cv::KeyPoint &k : kps) pts.push_back(k.pt);
    return pts;
}

std::vector<cv::Vec2d> box_corners(const cv::Mat &gray, const cv::Rect2f &box, const std::vector<cv::Vec2d> &existing,
                                   const BoxFeatureParams &p) {
    const float mx = float(p.inner_margin_frac) * box.width, mt = float(p.inner_margin_frac) * box.height;
    const float mb = float(p.bottom_margin_frac) * box.height;
    const cv::Rect inner = cv::Rect(cv::Point(int(std::lround(box.x + mx)), int(std::lround(box.y + mt))),
                                    cv::Point(int(std::lround(box.x + box.width - mx)),
                                              int(std::lround(box.y + box.height - mb)))) &
                           cv::Rect(0, 0, gray.cols, gray.rows);
    std::vector<cv::Vec2d> out;
    if (inner.width < 5 || inner.height < 5) return out;
    const cv::Mat roi = gray(inner);
    std::vector<cv::Point2f> found;
    if (p.detector == "fast") {
        found = fast_corners_strongest_first(roi, p.fast_threshold);
    } else {
        cv::goodFeaturesToTrack(roi, found, std::max(1, 2 * p.max_per_vehicle), p.quality, p.min_distance_px, cv::noArray(),
                                3, p.detector == "harris", 0.04);
    }
    const double d2 = p.min_distance_px * p.min_distance_px;
    for (const cv::Point2f &f : found) {
        const cv::Vec2d c(f.x + inner.x, f.y + inner.y);
        bool near = false;
        for (const cv::Vec2d &e : existing) near = near || (c - e).dot(c - e) < d2;
        for (const cv::Vec2d &e : out) near = near || (c - e).dot(c - e) < d2;
        if (near) continue;
        out.push_back(c);
        if (int(out.size()) >= p.max_per_vehicle) break;
    }
    return out;
}

void PointFlow::next_frame(const cv::Mat &gray) {
    std::swap(prev_, cur_);
    gray.copyTo(cur_);  // into the buffer of two frames ago: no allocation once running
}

void PointFlow::track(const std::vector<cv::Point2f> &pts, std::vector<cv::Point2f> &out, std::vector<uchar> &ok) const {
    out.clear();
    ok.assign(pts.size(), 0);
    if (pts.empty() || !ready() || prev_.size() != cur_.size()) return;
    // The region: the points' bounding box plus the margin, clipped to the frame.
    float x0 = pts[0].x, x1 = x0, y0 = pts[0].y, y1 = y0;
    for (const cv::Point2f &q : pts) {
        x0 = std::min(x0, q.x); x1 = std::max(x1, q.x);
        y0 = std::min(y0, q.y); y1 = std::max(y1, q.y);
    }
    const int m = p_.roi_margin_px;
    const cv::Rect roi = cv::Rect(cv::Point(int(std::floor(x0)) - m, int(std::floor(y0)) - m),
                                  cv::Point(int(std::ceil(x1)) + m + 1, int(std::ceil(y1)) + m + 1)) &
                         cv::Rect(0, 0, cur_.cols, cur_.rows);
    if (roi.width < 2 || roi.height < 2) return;
    const cv::Size win(p_.lk_window_px, p_.lk_window_px);
    const cv::Point2f off(float(roi.x), float(roi.y));
    std::vector<cv::Mat> pyr0, pyr1;
    const int levels = cv::buildOpticalFlowPyramid(prev_(roi), pyr0, win, p_.lk_levels, false);
    cv::buildOpticalFlowPyramid(cur_(roi), pyr1, win, levels, false);
    std::vector<cv::Point2f> local(pts);
    for (cv::Point2f &q : local) q -= off;
    const cv::TermCriteria term(cv::TermCriteria::COUNT | cv::TermCriteria::EPS, p_.lk_iterations, 0.03);
    std::vector<uchar> st_f, st_b;
    std::vector<float> err;
    std::vector<cv::Point2f> back;
    cv::calcOpticalFlowPyrLK(pyr0, pyr1, local, out, st_f, err, win, levels, term);
    cv::calcOpticalFlowPyrLK(pyr1, pyr0, out, back, st_b, err, win, levels, term);
    const double fb2 = p_.fb_max_px * p_.fb_max_px;
    for (size_t i = 0; i < pts.size(); ++i) {
        const cv::Point2f d = back[i] - local[i];
        ok[i] = st_f[i] && st_b[i] && double(d.dot(d)) <= fb2;
        out[i] += off;
    }
}

} // namespace hw
