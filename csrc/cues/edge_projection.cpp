#include "cues/edge_projection.hpp"

#include <opencv2/imgproc.hpp>

#include <algorithm>
#include <cmath>
#include <stdexcept>

namespace hw {

namespace {

void check_roi(const cv::Mat &gray, const cv::Rect &roi) {
    CV_Assert(gray.type() == CV_8UC1);
    if (roi.width <= 0 || roi.height <= 0 || (roi & cv::Rect(0, 0, gray.cols, gray.rows)) != roi)
        throw std::invalid_argument("edge projection: ROI empty or outside the image");
}

} // namespace

std::vector<float> vertical_edge_profile(const cv::Mat &gray, const cv::Rect &roi) {
    check_roi(gray, roi);
    cv::Mat gx;
    cv::Sobel(gray(roi), gx, CV_16S, 1, 0, 3);
    std::vector<int> sum(size_t(roi.width), 0);
    for (int y = 0; y < roi.height; ++y) {
        const short *g = gx.ptr<short>(y);
        for (int x = 0; x < roi.width; ++x) sum[size_t(x)] += std::abs(int(g[x]));
    }
    std::vector<float> w(size_t(roi.width));
    const float norm = 1.f / (4.f * roi.height);
    for (size_t x = 0; x < w.size(); ++x) w[x] = sum[x] * norm;
    return w;
}

std::vector<float> shadow_edge_profile(const cv::Mat &gray, const cv::Rect &roi, int dark) {
    check_roi(gray, roi);
    if (roi.y < 1) throw std::invalid_argument("shadow_edge_profile: ROI must start below row 0");
    cv::Mat gy;
    cv::Sobel(gray(roi), gy, CV_16S, 0, 1, 3);
    std::vector<float> v(size_t(roi.height), 0.f);
    const float norm = 1.f / (4.f * roi.width);
    for (int y = 0; y < roi.height; ++y) {
        const short *g = gy.ptr<short>(y);
        const uint8_t *above = gray.ptr<uint8_t>(roi.y + y - 1) + roi.x;
        int s = 0;
        for (int x = 0; x < roi.width; ++x)
            if (g[x] > 0 && above[x] <= dark) s += g[x];
        v[size_t(y)] = s * norm;
    }
    return v;
}

int argmax(const std::vector<float> &v, int from, int to) {
    from = std::max(0, from);
    to = std::min(int(v.size()), to);
    int best = from;
    for (int i = from; i < to; ++i)
        if (v[size_t(i)] > v[size_t(best)]) best = i;
    return best;
}

float peak_position(const std::vector<float> &v, int i) {
    if (i <= 0 || i + 1 >= int(v.size())) return float(i);
    const float a = v[size_t(i - 1)], b = v[size_t(i)], c = v[size_t(i + 1)];
    const float den = a - 2.f * b + c;
    if (den >= 0.f) return float(i);  // not a strict maximum
    return float(i) + std::clamp(0.5f * (a - c) / den, -0.5f, 0.5f);
}

SidePair outer_sides(const std::vector<float> &w, int split) {
    SidePair s;
    const int n = int(w.size());
    if (split <= 0 || split >= n) return s;
    const float half_l = 0.5f * w[size_t(argmax(w, 0, split))], half_r = 0.5f * w[size_t(argmax(w, split, n))];
    for (int x = 0; x < split && s.left < 0; ++x)
        if (w[size_t(x)] >= half_l) s.left = x;
    for (int x = n - 1; x >= split && s.right < 0; --x)
        if (w[size_t(x)] >= half_r) s.right = x;
    s.left_strength = w[size_t(s.left)];
    s.right_strength = w[size_t(s.right)];
    return s;
}

std::vector<float> side_prior(const std::vector<float> &w, float left, float right, float sigma) {
    std::vector<float> out(w.size());
    const float inv = 1.f / std::max(0.25f, sigma), mid = 0.5f * (left + right);
    for (size_t x = 0; x < w.size(); ++x) {
        const float d = (float(x) < mid ? float(x) - left : float(x) - right) * inv;
        out[x] = w[x] * std::exp(-0.5f * d * d);
    }
    return out;
}

SidePair best_side_pair(const std::vector<float> &w, int min_sep, int max_sep) {
    SidePair s;
    const int n = int(w.size());
    min_sep = std::max(1, min_sep);
    float best = -1.f;
    for (int l = 0; l + min_sep < n; ++l)
        for (int r = l + min_sep; r < n && r - l <= max_sep; ++r) {
            const float weaker = std::min(w[size_t(l)], w[size_t(r)]);
            if (weaker > best) { best = weaker; s.left = l; s.right = r; }
        }
    if (s.left >= 0) { s.left_strength = w[size_t(s.left)]; s.right_strength = w[size_t(s.right)]; }
    return s;
}

SidePair two_threshold_sides(const std::vector<float> &w, int pred_left, int pred_right, int window,
                             float max_change) {
    const int n = int(w.size());
    // Side windows, kept apart at the predicted centre.
    const int mid = (pred_left + pred_right) / 2;
    const int l0 = std::max(0, pred_left - window), l1 = std::min({n, pred_left + window + 1, mid});
    const int r0 = std::max({0, pred_right - window, mid}), r1 = std::min(n, pred_right + window + 1);
    if (l0 >= l1 || r0 >= r1) return {};
    const int il = argmax(w, l0, l1), ir = argmax(w, r0, r1);
    // Threshold 1: half the largest projection value, first column reaching it from the outside.
    const float half = 0.5f * std::max(w[size_t(il)], w[size_t(ir)]);
    SidePair s;
    for (int x = l0; x < l1 && s.left < 0; ++x)
        if (w[size_t(x)] >= half) s.left = x;
    for (int x = r1 - 1; x >= r0 && s.right < 0; --x)
        if (w[size_t(x)] >= half) s.right = x;
    // Threshold 2: the largest value of the window, for a side that jumped.
    if (s.left < 0 || std::abs(s.left - pred_left) > max_change) s.left = il;
    if (s.right < 0 || std::abs(s.right - pred_right) > max_change) s.right = ir;
    s.left_strength = w[size_t(s.left)];
    s.right_strength = w[size_t(s.right)];
    return s;
}

} // namespace hw
