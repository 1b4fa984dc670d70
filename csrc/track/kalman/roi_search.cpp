#include "track/kalman/roi_search.hpp"

#include "cues/edge_projection.hpp"

#include <algorithm>
#include <cmath>

namespace hw {

float road_gray_below(const cv::Mat &gray, float x1, float y1, float x2) {
    // A strip a tenth of the width high (at least 2 rows), two rows under the edge.
    const int w = int(std::lround(x2 - x1));
    const int top = int(std::lround(y1)) + 2, h = std::max(2, w / 10);
    cv::Rect strip(int(std::lround(x1)), top, w, h);
    strip &= cv::Rect(0, 0, gray.cols, gray.rows);
    if (strip.width < 2 || strip.height < 1) return kNaN;
    std::vector<uint8_t> v;
    v.reserve(size_t(strip.area()));
    for (int y = strip.y; y < strip.y + strip.height; ++y) {
        const uint8_t *row = gray.ptr<uint8_t>(y);
        v.insert(v.end(), row + strip.x, row + strip.x + strip.width);
    }
    std::nth_element(v.begin(), v.begin() + long(v.size() / 2), v.end());
    return float(v[v.size() / 2]);
}

RoiMeasurement search_roi(const cv::Mat &gray, const RoiPrediction &pred, const ShadowEdgeParams &edge,
                          const VerifyParams &verify, const RoiSearchParams &p) {
    CV_Assert(!gray.empty() && gray.type() == CV_8UC1);
    RoiMeasurement m;
    const cv::Rect image(0, 0, gray.cols, gray.rows);
    const float w_pred = pred.x2 - pred.x1;
    if (!(w_pred >= 4.f) || !std::isfinite(pred.y1)) return m;

    // Road level under the predicted bottom, for the adaptive thresholds of the shadow stage.
    float road = road_gray_below(gray, pred.x1, pred.y1 + pred.gate_y, pred.x2);
    if (!std::isfinite(road)) return m;
    const ShadowThresholds thr = shadow_thresholds(road, edge);

    // Bottom: rows within the gate; the shadow-edge profile of the inner 70 % of the columns (away
    // from neighbours) minus the weaker of two strips beside the vehicle. A shadow edge that runs on
    // beside the vehicle on both sides (an overpass or tree shadow across the road) is not its
    // bottom, however strong: without this the band's edge captures the track and drags it along.
    const int gy = std::max(2, int(std::ceil(pred.gate_y)));
    const int y0 = std::max(1, int(std::lround(pred.y1)) - gy), y1r = std::min(gray.rows - 1, int(std::lround(pred.y1)) + gy + 1);
    if (y1r - y0 < 3) return m;
    auto profile = [&](float xa, float xb) {
        cv::Rect r(int(std::lround(xa)), y0, int(std::lround(xb - xa)), y1r - y0);
        r &= image;
        if (r.width < 2 || r.height != y1r - y0) return std::vector<float>(size_t(y1r - y0), 0.f);
        return shadow_edge_profile(gray, r, thr.dark);
    };
    std::vector<float> v = profile(pred.x1 + 0.15f * w_pred, pred.x2 - 0.15f * w_pred);
    const std::vector<float> left = profile(pred.x1 - 0.4f * w_pred, pred.x1 - 0.1f * w_pred);
    const std::vector<float> right = profile(pred.x2 + 0.1f * w_pred, pred.x2 + 0.4f * w_pred);
    for (size_t i = 0; i < v.size(); ++i) v[i] -= std::min(left[i], right[i]);
    const int iy = argmax(v, 0, int(v.size()));
    if (v[size_t(iy)] < p.bottom_min_frac * thr.grad / 4.0) return m;  // profile is in gray levels
    const float y1 = y0 + peak_position(v, iy);

    // Sides: ROI on the measured bottom, widened by the margin and the gate.
    const float margin = std::max(float(verify.margin_px), float(verify.margin_frac) * w_pred) + pred.gate_x;
    const int height = std::max(3, int(std::lround(verify.roi_height_frac * w_pred)));
    cv::Rect roi(int(std::floor(pred.x1 - margin)), int(std::lround(y1)) - height,
                 int(std::ceil(w_pred + 2.f * margin)), height);
    roi &= image;
    if (roi.width < 8 || roi.height < 3) return m;
    const std::vector<float> w = vertical_edge_profile(gray, roi);
    const int pl = int(std::lround(pred.x1)) - roi.x, pr = int(std::lround(pred.x2)) - roi.x;
    // Prior of the prediction (sigma: the innovation's), so that of two similar edges in the gate
    // (the vehicle's own side and a neighbour's next to it) the expected one wins; the two-threshold
    // rule then runs on the weighted profile.
    const std::vector<float> wp = side_prior(w, float(pl), float(pr), pred.sigma_x);
    SidePair s = two_threshold_sides(wp, pl, pr, int(std::ceil(pred.gate_x)) + 1, pred.max_side_change);
    if (!s.found()) return m;
    s.left_strength = w[size_t(s.left)];
    s.right_strength = w[size_t(s.right)];
    const float t_side = side_threshold(road, verify);
    if (s.weaker() < t_side) return m;
    const float x1 = roi.x + peak_position(w, s.left), x2 = roi.x + peak_position(w, s.right);
    if (std::abs((x2 - x1) / w_pred - 1.f) > p.max_scale_change) return m;
    if (std::abs(x1 - pred.x1) > pred.gate_x + 1.f || std::abs(x2 - pred.x2) > pred.gate_x + 1.f) return m;

    m.found = true;
    m.x1 = x1; m.y1 = y1; m.x2 = x2;
    m.side_excess = s.weaker() / std::max(1e-3f, t_side);
    m.road_gray = road;
    return m;
}

float RoiSearch::expected_width(float y, cv::Size size, const LaneModel &lanes, const CameraParams &cam) const {
    return expected_vehicle_width(y, size, lanes, cam, prior_);
}

} // namespace hw
