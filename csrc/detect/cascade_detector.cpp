#include "detect/cascade_detector.hpp"
#include "detect/vehicle_verifier.hpp"

#include <opencv2/imgproc.hpp>
#include <opencv2/objdetect.hpp>

#include <algorithm>
#include <cmath>
#include <stdexcept>

namespace hw {

CascadeDetector::CascadeDetector(const CascadeParams &p) : p_(p), cc_(std::make_unique<cv::CascadeClassifier>()) {
    if (p_.model.empty())
        throw std::invalid_argument("cascade.model: no cascade XML given (Headway's Python side fills in the shipped one)");
    if (!cc_->load(p_.model))
        throw std::invalid_argument("cascade.model: OpenCV cannot load '" + p_.model +
                                    "' as a cascade XML; train one with `headway train cascade` or leave the key empty");
    win_ = cc_->getOriginalWindowSize();
    if (!p_.verifier.empty() && p_.verifier != "off") verifier_ = make_vehicle_verifier(p_.verifier);
    if (p_.max_vehicle_height_m <= p_.min_vehicle_height_m)
        throw std::invalid_argument("cascade.max_vehicle_height_m must exceed cascade.min_vehicle_height_m");
}

CascadeDetector::~CascadeDetector() = default;

namespace {

struct Raw {
    cv::Rect2f box;
    float weight;
};

} // namespace

std::vector<CascadeDetection> CascadeDetector::detect(const cv::Mat &gray, const LaneModel &lanes,
                                                      const CameraParams &cam) const {
    CV_Assert(gray.type() == CV_8UC1);
    const RoadPrior prior = make_road_prior(gray.size(), lanes, cam, p_.road);
    std::vector<Raw> raw;
    if (prior.empty()) return {};
    const double yh = prior.horizon_row, hc = cam.height_m;
    const double max_h = p_.max_window_frac * gray.rows;
    std::vector<cv::Rect> rects;
    std::vector<int> levels;
    std::vector<double> weights;
    cv::Mat band;
    for (double f = 1.0; win_.height * f <= max_h; f *= p_.scale_factor) {
        const double hs = win_.height * f, ws = win_.width * f;
        // rows where the window's bottom may lie (flat road, vehicle heights H_min..H_max)
        const double yb0 = std::max<double>(prior.y_top, yh + hs * hc / p_.max_vehicle_height_m);
        const double yb1 = std::min<double>(gray.rows, yh + hs * hc / p_.min_vehicle_height_m);
        if (yb1 <= yb0) continue;
        // columns: the road area at those rows, half a window wider each side
        int xl = gray.cols, xr = -1;
        for (int y = int(yb0); y < std::min<int>(int(std::ceil(yb1)), prior.y_bottom); ++y) {
            if (!prior.contains_row(y) || prior.left(y) > prior.right(y)) continue;
            xl = std::min(xl, prior.left(y));
            xr = std::max(xr, prior.right(y));
        }
        if (xr < xl) {  // bottom rows below the scanned road (near vehicles): the last road row's span
            const int y = prior.y_bottom - 1;
            if (yb1 < prior.y_bottom || prior.left(y) > prior.right(y)) continue;
            xl = prior.left(y); xr = prior.right(y);
        }
        const int x0 = std::max(0, int(xl - ws / 2)), x1 = std::min(gray.cols, int(xr + ws / 2) + 1);
        const int y0 = std::max(0, int(yb0 - hs)), y1 = std::min(gray.rows, int(std::ceil(yb1)) + 1);
        if (x1 - x0 < ws + 1 || y1 - y0 < hs + 1) continue;
        const cv::Mat roi = gray(cv::Rect(x0, y0, x1 - x0, y1 - y0));
        const cv::Size sz(int(std::lround(roi.cols / f)), int(std::lround(roi.rows / f)));
        if (sz.width <= win_.width || sz.height <= win_.height) continue;
        if (f > 1.0) cv::resize(roi, band, sz, 0, 0, cv::INTER_LINEAR);
        else band = roi;
        rects.clear(); levels.clear(); weights.clear();
        cc_->detectMultiScale(band, rects, levels, weights, 1.5, 0, 0, win_, win_, true);
        for (size_t i = 0; i < rects.size(); ++i) {
            if (p_.step_px > 2 && (rects[i].x % p_.step_px || rects[i].y % p_.step_px)) continue;
            raw.push_back({cv::Rect2f(float(x0 + rects[i].x * f), float(y0 + rects[i].y * f), float(ws), float(hs)),
                           float(weights[i])});
        }
    }
    // group: strongest first, every window overlapping a group's seed joins it. OpenCV's detectMultiScale scans in
    // parallel and returns the windows in a thread-dependent order, and stage sums tie (they are sums of a few
    // stump values): a total order (sum, then position) makes the groups, hence the tracks, the same on every run.
    std::sort(raw.begin(), raw.end(), [](const Raw &a, const Raw &b) {
        if (a.weight != b.weight) return a.weight > b.weight;
        if (a.box.y != b.box.y) return a.box.y < b.box.y;
        if (a.box.x != b.box.x) return a.box.x < b.box.x;
        return a.box.width < b.box.width;
    });
    std::vector<char> used(raw.size(), 0);
    std::vector<CascadeDetection> out;
    for (size_t i = 0; i < raw.size(); ++i) {
        if (used[i]) continue;
        double l = 0, t = 0, r = 0, b = 0;
        int n = 0;
        for (size_t j = i; j < raw.size(); ++j) {
            if (used[j] || box_iou(raw[i].box, raw[j].box) < p_.group_iou) continue;
            used[j] = 1;
            ++n;
            l += raw[j].box.x; t += raw[j].box.y; r += raw[j].box.br().x; b += raw[j].box.br().y;
        }
        if (n < p_.min_neighbors) continue;
        CascadeDetection d;
        d.box = cv::Rect2f(float(l / n), float(t / n), float((r - l) / n), float((b - t) / n));
        d.neighbors = n;
        d.stage_sum = raw[i].weight;
        d.confidence = float(n / (n + p_.neighbors_half));
        out.push_back(d);
    }
    if (verifier_) {  // every group of the frame at once (the CNN verifier runs them as one batch)
        std::vector<cv::Rect2f> boxes;
        std::vector<int> ns;
        for (const auto &d : out) { boxes.push_back(d.box); ns.push_back(d.neighbors); }
        const std::vector<float> p = verifier_->probabilities(gray, boxes, ns, cam.horizon_row(), hc);
        for (size_t i = 0; i < out.size(); ++i) out[i].confidence = p[i];
    }
    if (p_.nms_iou >= 1.0) return out;
    // non-maximum suppression by confidence: most confident first, drop what overlaps a kept one
    std::stable_sort(out.begin(), out.end(),
                     [](const CascadeDetection &a, const CascadeDetection &b) { return a.confidence > b.confidence; });
    std::vector<CascadeDetection> kept;
    for (const auto &d : out) {
        bool dup = false;
        for (const auto &k : kept) dup = dup || box_iou(d.box, k.box) >= p_.nms_iou;
        if (!dup) kept.push_back(d);
    }
    return kept;
}

} // namespace hw
