#include "cues/vehicle_top.hpp"

#include "base/types.hpp"

#include <algorithm>
#include <cmath>
#include <vector>

namespace hw {

namespace {

// Vertical-edge strength at row y near column c: max over c-1..c+1 of |I(x+1) - I(x-1)| / 2.
float side_edge(const cv::Mat &gray, int y, int c) {
    const uint8_t *row = gray.ptr<uint8_t>(y);
    float best = 0.f;
    for (int x = std::max(1, c - 1); x <= std::min(gray.cols - 2, c + 1); ++x)
        best = std::max(best, 0.5f * std::abs(float(row[x + 1]) - float(row[x - 1])));
    return best;
}

} // namespace

float vehicle_top(const cv::Mat &gray, float left, float right, float bottom, const TopSearch &p) {
    const float w = right - left;
    if (!(w >= 6.f) || !std::isfinite(bottom)) return kNaN;
    return vehicle_top_between(gray, left, right, bottom, w, int(std::floor(bottom - float(p.max_aspect) * w)),
                               bottom - float(p.min_aspect) * w, true, true, p.keep_frac, p.max_gap);
}

float vehicle_top_between(const cv::Mat &gray, float left, float right, float bottom, float ref_w, int y_min,
                          float y_max, bool use_left, bool use_right, double keep_frac, int max_gap) {
    CV_Assert(!gray.empty() && gray.type() == CV_8UC1);
    const float w = right - left;
    if (!(w >= 6.f) || !std::isfinite(bottom) || !(ref_w > 0.f) || !(use_left || use_right)) return kNaN;
    const int cl = int(std::lround(left)), cr = int(std::lround(right));
    if ((use_left && (cl < 1 || cl > gray.cols - 2)) || (use_right && (cr < 1 || cr > gray.cols - 2))) return kNaN;
    // The sides followed at once: the weaker of the two edges per row (or the one side).
    auto edge = [&](int y) {
        if (!use_left) return side_edge(gray, y, cr);
        if (!use_right) return side_edge(gray, y, cl);
        return std::min(side_edge(gray, y, cl), side_edge(gray, y, cr));
    };

    // Typical strength on the lower body, above wheels and underbody shadow.
    const auto [ref_lo, ref_hi] = lower_body_rows(bottom, ref_w);
    y_min = std::max(0, y_min);
    if (ref_lo < y_min || ref_hi > gray.rows - 1 || ref_hi <= ref_lo) return kNaN;
    std::vector<float> ref;
    for (int y = ref_lo; y <= ref_hi; ++y) ref.push_back(edge(y));
    std::nth_element(ref.begin(), ref.begin() + long(ref.size() / 2), ref.end());
    const float typical = ref[ref.size() / 2];
    if (typical < 2.f) return kNaN;  // no sides to follow (gray levels)

    // Up from the lower body while the sides carry an edge, bridging short gaps.
    const float keep = float(keep_frac) * typical;
    int last = ref_lo, gap = 0;
    for (int y = ref_lo - 1; y >= y_min && gap <= max_gap; --y) {
        if (edge(y) >= keep) { last = y; gap = 0; }
        else ++gap;
    }
    if (last <= y_min) return kNaN;  // still going at the search limit: background edges, not a roof
    const float top = float(last) - 0.5f;
    if (top > y_max) return kNaN;
    // A roof closes the sides: a horizontal edge across the inner columns at the top (within a row).
    // Without it the "sides" were lines running on (lane markings, poles), not a vehicle.
    const int xa = std::max(0, cl + 1), xb = std::min(gray.cols - 1, cr - 1);
    float roof = 0.f;
    for (int y = std::max(1, last - 1); y <= std::min(gray.rows - 2, last + 1); ++y) {
        const uint8_t *up = gray.ptr<uint8_t>(y - 1), *down = gray.ptr<uint8_t>(y + 1);
        float s = 0.f;
        for (int x = xa; x <= xb; ++x) s += 0.5f * std::abs(float(down[x]) - float(up[x]));
        roof = std::max(roof, s / float(std::max(1, xb - xa + 1)));
    }
    return roof >= keep ? top : kNaN;
}

float snap_side(const cv::Mat &gray, float x, int y0, int y1, float radius) {
    CV_Assert(!gray.empty() && gray.type() == CV_8UC1);
    y0 = std::max(y0, 0);
    y1 = std::min(y1, gray.rows - 1);
    const int a = std::max(1, int(std::floor(x - radius))), b = std::min(gray.cols - 2, int(std::ceil(x + radius)));
    if (y1 < y0 || b < a) return x;
    // |I(c+1) - I(c-1)| / 2 summed over the rows, per column c.
    std::vector<float> prof(size_t(b - a + 1), 0.f);
    for (int y = y0; y <= y1; ++y) {
        const uint8_t *row = gray.ptr<uint8_t>(y);
        for (int c = a; c <= b; ++c) prof[size_t(c - a)] += 0.5f * std::abs(float(row[c + 1]) - float(row[c - 1]));
    }
    const auto best = std::max_element(prof.begin(), prof.end());
    return *best > 0.f ? float(a + int(best - prof.begin())) : x;
}

} // namespace hw
