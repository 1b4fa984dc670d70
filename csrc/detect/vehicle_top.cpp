#include "detect/vehicle_top.hpp"

#include "core/types.hpp"

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
    CV_Assert(!gray.empty() && gray.type() == CV_8UC1);
    const float w = right - left;
    if (!(w >= 6.f) || !std::isfinite(bottom)) return kNaN;
    const int cl = int(std::lround(left)), cr = int(std::lround(right));
    if (cl < 1 || cr > gray.cols - 2) return kNaN;
    // Both sides at once: the weaker of the two edges per row.
    auto edge = [&](int y) { return std::min(side_edge(gray, y, cl), side_edge(gray, y, cr)); };

    // Typical strength on the lower body, above wheels and underbody shadow.
    const int ref_lo = int(std::lround(bottom - 0.45f * w)), ref_hi = int(std::lround(bottom - 0.15f * w));
    const int y_min = std::max(0, int(std::floor(bottom - float(p.max_aspect) * w)));
    if (ref_lo < y_min || ref_hi > gray.rows - 1 || ref_hi <= ref_lo) return kNaN;
    std::vector<float> ref;
    for (int y = ref_lo; y <= ref_hi; ++y) ref.push_back(edge(y));
    std::nth_element(ref.begin(), ref.begin() + long(ref.size() / 2), ref.end());
    const float typical = ref[ref.size() / 2];
    if (typical < 2.f) return kNaN;  // no sides to follow (gray levels)

    // Up from the lower body while both sides carry an edge, bridging short gaps.
    const float keep = float(p.keep_frac) * typical;
    int last = ref_lo, gap = 0;
    for (int y = ref_lo - 1; y >= y_min && gap <= p.max_gap; --y) {
        if (edge(y) >= keep) { last = y; gap = 0; }
        else ++gap;
    }
    if (last <= y_min) return kNaN;  // still going at the search limit: background edges, not a roof
    const float top = float(last) - 0.5f;
    if (bottom - top < float(p.min_aspect) * w) return kNaN;
    // A roof closes the two sides: a horizontal edge across the inner columns at the top (within a
    // row). Without it the "sides" were lines running on (lane markings, poles), not a vehicle.
    float roof = 0.f;
    for (int y = std::max(1, last - 1); y <= std::min(gray.rows - 2, last + 1); ++y) {
        const uint8_t *up = gray.ptr<uint8_t>(y - 1), *down = gray.ptr<uint8_t>(y + 1);
        float s = 0.f;
        for (int x = cl + 1; x < cr; ++x) s += 0.5f * std::abs(float(down[x]) - float(up[x]));
        roof = std::max(roof, s / float(std::max(1, cr - cl - 1)));
    }
    return roof >= keep ? top : kNaN;
}

} // namespace hw
