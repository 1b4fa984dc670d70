#include "track/kalman/template_check.hpp"

#include <opencv2/imgproc.hpp>

#include <algorithm>
#include <cmath>

namespace hw {

namespace {

cv::Rect to_pixels(const cv::Rect2f &r) {
    const int x0 = int(std::floor(r.x)), y0 = int(std::floor(r.y));
    return {x0, y0, std::max(1, int(std::ceil(r.x + r.width)) - x0), std::max(1, int(std::ceil(r.y + r.height)) - y0)};
}

} // namespace

VehicleTemplate make_template(const cv::Mat &gray, const cv::Rect2f &box, int template_px, double min_std_gray) {
    CV_Assert(!gray.empty() && gray.type() == CV_8UC1 && template_px >= 4);
    VehicleTemplate t;
    const cv::Rect r = to_pixels(box);
    const cv::Rect in = r & cv::Rect(0, 0, gray.cols, gray.rows);
    if (in.area() < 0.9 * r.area() || in.width < 4 || in.height < 4) return t;
    cv::Scalar mean, stddev;
    cv::meanStdDev(gray(in), mean, stddev);
    if (stddev[0] < min_std_gray) return t;  // a flat patch correlates with anything flat
    t.scale = std::min(1.f, float(template_px) / float(in.width));
    cv::resize(gray(in), t.patch, cv::Size(), t.scale, t.scale, cv::INTER_AREA);
    if (t.patch.cols < 3 || t.patch.rows < 3) t.patch.release();
    t.box = cv::Rect2f(in);
    return t;
}

TemplateMatch match_template(const cv::Mat &gray, const VehicleTemplate &t, const cv::Rect2f &at, float search_px) {
    TemplateMatch m;
    if (!t.usable()) return m;
    // Search window: the box at `at` (template size) grown by search_px each side, in image px.
    const float s = std::max(0.f, search_px);
    const cv::Rect win = to_pixels(cv::Rect2f(at.x - s, at.y - s, t.box.width + 2 * s, t.box.height + 2 * s)) &
                         cv::Rect(0, 0, gray.cols, gray.rows);
    if (win.width < 4 || win.height < 4) return m;
    cv::Mat small;
    cv::resize(gray(win), small, cv::Size(), t.scale, t.scale, cv::INTER_AREA);
    if (small.cols < t.patch.cols || small.rows < t.patch.rows) return m;
    cv::Mat score;
    cv::matchTemplate(small, t.patch, score, cv::TM_CCOEFF_NORMED);
    double best;
    cv::Point loc;
    cv::minMaxLoc(score, nullptr, &best, nullptr, &loc);
    m.ncc = float(best);
    // Back to image px: the match's top-left corner relative to `at`.
    m.shift = cv::Point2f(win.x + loc.x / t.scale - at.x, win.y + loc.y / t.scale - at.y);
    return m;
}

} // namespace hw
