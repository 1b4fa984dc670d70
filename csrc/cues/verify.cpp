#include "cues/verify.hpp"

#include "base/sections.hpp"
#include "cues/edge_projection.hpp"

#include <opencv2/imgproc.hpp>

#include <algorithm>
#include <cmath>

namespace hw {

namespace {

// Texture of the road under a bottom edge: mean (|S_x| + |S_y|) / 4 over a strip 0.15 widths high
// two rows below it, divided by the strip's mean gray level; NaN when the strip leaves the image.
float texture_below(const cv::Mat &gray, float left, float right, float bottom) {
    const int w = int(std::lround(right - left));
    cv::Rect strip(int(std::lround(left)), int(std::lround(bottom)) + 2, w, std::max(3, int(0.15f * w)));
    if ((strip & cv::Rect(0, 0, gray.cols, gray.rows)) != strip || strip.width < 3) return kNaN;
    cv::Mat gx, gy;
    cv::Sobel(gray(strip), gx, CV_16S, 1, 0, 3);
    cv::Sobel(gray(strip), gy, CV_16S, 0, 1, 3);
    const double grad = (cv::sum(cv::abs(gx))[0] + cv::sum(cv::abs(gy))[0]) / (4.0 * strip.area());
    return float(grad / std::max(1.0, cv::mean(gray(strip))[0]));
}

} // namespace

bool verify_one(const cv::Mat &gray, const ShadowHypothesis &h, const VerifyParams &p, Detection &out) {
    const float w_exp = h.expected_width_px;
    const float w_shadow = h.box.width;
    const float bottom = h.box.y + h.box.height;
    if (!(w_exp > 0.f) || !std::isfinite(bottom)) return false;
    const float ratio = w_shadow / w_exp;
    if (ratio < p.shadow_min_ratio) return false;  // too narrow for a vehicle at this row
    const bool long_shadow = ratio > p.shadow_max_ratio;

    // ROI: the edge widened by the margin each side, roi_height_frac of the vehicle width high.
    const float w_ref = long_shadow ? w_exp : w_shadow;
    const int margin = int(std::lround(std::max(double(p.margin_px), p.margin_frac * w_ref)));
    const int height = std::max(3, int(std::lround(p.roi_height_frac * w_ref)));
    const int yb = int(std::lround(bottom));
    cv::Rect roi(int(std::floor(h.box.x)) - margin, yb - height, int(std::lround(w_shadow)) + 2 * margin,
                 height);
    roi &= cv::Rect(0, 0, gray.cols, gray.rows);
    if (roi.width < 8 || roi.height < 3) return false;

    const std::vector<float> w = vertical_edge_profile(gray, roi);
    SidePair s;
    if (long_shadow) {
        s = best_side_pair(w, int(p.box_min_ratio * w_exp), int(p.box_max_ratio * w_exp));
    } else {
        // The shadow's ends are where the sides are expected (prior sigma: half the margin).
        const float left = h.box.x - roi.x, right = left + w_shadow;
        s = outer_sides(side_prior(w, left, right, 0.5f * margin), int(std::lround(0.5f * (left + right))));
    }
    if (!s.found()) return false;
    s.left_strength = w[size_t(s.left)];
    s.right_strength = w[size_t(s.right)];
    // Two sides, each standing out against the road's own contrast level.
    const float t_side = side_threshold(h.road_gray, p);
    if (s.weaker() < t_side) return false;
    const float left = roi.x + peak_position(w, s.left), right = roi.x + peak_position(w, s.right);
    const float width = right - left;
    if (width < p.box_min_ratio * w_exp || width > p.box_max_ratio * w_exp) return false;

    const float texture = texture_below(gray, left, right, bottom);
    if (texture > p.road_texture_max) return false;  // not standing on a road

    const float top = p.find_top ? vehicle_top(gray, left, right, bottom, p.top) : kNaN;
    const float box_h = std::isfinite(top) ? bottom - top : float(p.shape.aspect) * width;
    out.box = cv::Rect2f(left, bottom - box_h, width, box_h);
    out.top_measured = std::isfinite(top);
    // Score: 0.5 when the weaker side just reaches its threshold, towards 1 as it grows, scaled
    // down for a faint shadow (strength = shadow step / road level; 0.5 is a deep shadow).
    const float side_excess = s.weaker() / std::max(1e-3f, t_side);
    out.score = (1.f - 0.5f / std::sqrt(side_excess)) * std::min(1.f, 0.5f + h.strength);
    return true;
}

float side_threshold(float road_gray, const VerifyParams &p) {
    return float(std::max(p.side_min_gray, p.side_rel * road_gray));
}

std::vector<Detection> verify_hypotheses(const cv::Mat &gray, const std::vector<ShadowHypothesis> &hyps,
                                         const LaneModel &, const CameraParams &,
                                         const VerifyParams &p) {
    CV_Assert(!gray.empty() && gray.type() == CV_8UC1);
    std::vector<Detection> found;
    for (const ShadowHypothesis &h : hyps) {
        Detection d;
        if (verify_one(gray, h, p, d)) found.push_back(d);
    }
    std::vector<Detection> out;
    for (size_t i : strongest_apart(found, p.nms_iou)) out.push_back(found[i]);
    return out;
}

std::vector<size_t> strongest_apart(const std::vector<Detection> &found, double nms_iou) {
    std::vector<size_t> order(found.size());
    for (size_t i = 0; i < order.size(); ++i) order[i] = i;
    std::stable_sort(order.begin(), order.end(), [&](size_t a, size_t b) { return found[a].score > found[b].score; });
    std::vector<size_t> out;
    for (size_t i : order) {
        bool overlapped = false;
        for (size_t k : out) overlapped = overlapped || box_iou(found[i].box, found[k].box) > nms_iou;
        if (!overlapped) out.push_back(i);
    }
    return out;
}

namespace {

// Its section, read by the shadow detector and the Kalman tracker's ROI search (base/sections.hpp).
const bool registered = register_section<VerifyParams>("verify");

} // namespace

} // namespace hw
