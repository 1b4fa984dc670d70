#include "lanes/dot_markings.hpp"

#include <algorithm>
#include <cmath>
#include <cstdint>
#include <limits>

namespace hw {

namespace {

// A chain of short bars in consecutive scanned rows, each within 2 px of the last.
struct Blob {
    float sx = 0.f, sy = 0.f, sc = 0.f;  // contrast-weighted sums of x and y, and the summed contrast
    float x_last = 0.f, y_last = 0.f, y_first = 0.f;
    bool dot = false;
    float x() const { return sx / sc; }
    float y() const { return sy / sc; }
};

constexpr float kJoinPx = 2.f;     // px; a bar continues a blob of the previous row this close
constexpr float kMinRowsApart = 3.f;  // rows; two candidates this close in row define no line

// A marking point or a short bar (marking_filter.hpp): a dot may be one on one of its rows and the other on the next.
struct Bar {
    MarkingPoint p;
    bool is_short = false;
};

// Blobs of the bars nearer than max_range_m and at most a dot wide (bars: sorted by row); owner[i]: blob of bar
// i or -1.
std::vector<Blob> join_blobs(const std::vector<Bar> &bars, const ScanBand &band, const CameraParams &cam,
                             const HorizonPrior &hp, const DotMarkingParams &p, std::vector<int> &owner) {
    std::vector<Blob> blobs;
    owner.assign(bars.size(), -1);
    const float y_h_hi = hp.row - hp.tol_px;  // highest horizon the prior allows: widest dot at a row
    const float y_far = row_at_range(cam, hp.row, float(p.max_range_m));
    size_t active = 0;  // blobs before this index ended above the previous scanned row
    for (size_t i = 0; i < bars.size(); ++i) {
        const MarkingPoint &b = bars[i].p;
        if (b.y < y_far || b.contrast < float(p.min_contrast)) continue;
        if (b.width > 1.5f * float(p.dot_m) * px_per_m(cam, y_h_hi, b.y) + 2.f) continue;
        // A line through the vanishing point moves |k| px per row (k from the prior, as the marking filter's runs).
        const float k =
            std::min(kMaxMarkingSlope, std::fabs(b.x - hp.vp_x) / std::max(1.f, b.y - (hp.row + hp.tol_px)));
        const float join_px = kJoinPx + k * float(band.step);
        while (active < blobs.size() && blobs[active].y_last < b.y - float(band.step)) ++active;
        int join = -1;
        for (size_t o = active; o < blobs.size(); ++o)
            if (blobs[o].y_last == b.y - float(band.step) && std::fabs(blobs[o].x_last - b.x) <= join_px) {
                join = int(o);
                break;
            }
        if (join < 0) {
            join = int(blobs.size());
            blobs.emplace_back();
            blobs.back().y_first = b.y;
        }
        Blob &o = blobs[size_t(join)];
        o.sx += b.contrast * b.x;
        o.sy += b.contrast * b.y;
        o.sc += b.contrast;
        o.x_last = b.x;
        o.y_last = b.y;
        owner[i] = join;
    }
    return blobs;
}

} // namespace

void add_dot_markings(const cv::Mat &gray, const std::vector<MarkingPoint> &short_bars, const ScanBand &band,
                      const CameraParams &cam, const HorizonPrior &hp, const DotMarkingParams &p, float vp_tol_px,
                      std::vector<MarkingPoint> &points) {
    // Blobs are joined over the marking points and the short bars together, both sorted by row.
    std::vector<Bar> bars;
    bars.reserve(points.size() + short_bars.size());
    for (const MarkingPoint &q : points) bars.push_back({q, false});
    for (const MarkingPoint &q : short_bars) bars.push_back({q, true});
    std::inplace_merge(bars.begin(), bars.begin() + long(points.size()), bars.end(),
                       [](const Bar &a, const Bar &b) { return row_order(a.p, b.p); });
    std::vector<int> owner;
    std::vector<Blob> blobs = join_blobs(bars, band, cam, hp, p, owner);

    // Candidates: blobs no longer along the road than a dot; a length L at d rows below the horizon spans
    // L d^2 / (fy h) rows (dZ = L, y = y_h + fy h / Z), plus two rows of blur.
    std::vector<int> cand;
    const float y_h_hi = hp.row - hp.tol_px;
    for (size_t k = 0; k < blobs.size(); ++k) {
        const Blob &o = blobs[k];
        const float d = std::max(1.f, o.y_last - y_h_hi);
        const float rows = float(p.max_length_m) * d * d / float(cam.fy * cam.height_m) + 2.f;
        if (o.y_last - o.y_first <= rows) cand.push_back(int(k));
    }
    // The strongest candidates (summed contrast) on the road, at most max_candidates. On the road: the brightest of
    // the four pixels 4 px left, right, above and below the blob's centre is at least road_frac of its row's median
    // (the road, sampled every 8 px); bright specks on a dark vehicle's body are not.
    std::sort(cand.begin(), cand.end(), [&](int a, int b) { return blobs[size_t(a)].sc > blobs[size_t(b)].sc; });
    std::vector<int> row_median(size_t(gray.rows), -1);  // computed once per row that holds a candidate
    std::vector<uint8_t> samples;
    auto on_road = [&](const Blob &o) {
        const int x = int(std::lround(o.x())), y = int(std::lround(o.y()));
        if (x < 4 || x >= gray.cols - 4 || y < 3 || y >= gray.rows - 3) return false;
        const uint8_t *row = gray.ptr<uint8_t>(y);
        int &median = row_median[size_t(y)];
        if (median < 0) {
            samples.clear();
            for (int i = 0; i < gray.cols; i += 8) samples.push_back(row[i]);
            std::nth_element(samples.begin(), samples.begin() + long(samples.size() / 2), samples.end());
            median = samples[samples.size() / 2];
        }
        const int ring = std::max({int(row[x - 4]), int(row[x + 4]), int(gray.at<uint8_t>(y - 3, x)),
                                   int(gray.at<uint8_t>(y + 3, x))});
        return float(ring) >= float(p.road_frac) * float(median);
    };
    size_t kept = 0;
    for (size_t c = 0; c < cand.size() && kept < size_t(p.max_candidates); ++c)
        if (p.road_frac <= 0.0 || on_road(blobs[size_t(cand[c])])) cand[kept++] = cand[c];
    cand.resize(kept);
    if (cand.size() < size_t(p.min_dots)) return;

    // Lines through two candidates that pass the expected vanishing point as a marking's does (within vp_tol_px of
    // it: |x(vp.y) - vp.x| / sqrt(1 + k^2), the Hough stage's wide window). Every candidate within tol of such a
    // line with at least min_dots on it (counted min_gap_m apart) is a dot.
    const cv::Point2f vp(hp.vp_x, hp.row);
    const size_t n = cand.size();
    std::vector<float> cx(n), cy(n);
    for (size_t i = 0; i < n; ++i) {
        cx[i] = blobs[size_t(cand[i])].x();
        cy[i] = blobs[size_t(cand[i])].y();
    }
    const float tol = float(p.line_tol_frac) * float(cam.width);
    std::vector<size_t> on_line;
    for (size_t i = 0; i < n; ++i)
        for (size_t j = i + 1; j < n; ++j) {
            if (blobs[size_t(cand[i])].dot && blobs[size_t(cand[j])].dot) continue;
            const float dy = cy[j] - cy[i];
            if (std::fabs(dy) < kMinRowsApart) continue;
            const float k = (cx[j] - cx[i]) / dy;  // x(y) = cx[i] + k (y - cy[i])
            if (std::fabs(k) > kMaxMarkingSlope) continue;
            if (std::fabs(cx[i] + k * (vp.y - cy[i]) - vp.x) > vp_tol_px * std::sqrt(1.f + k * k)) continue;
            const float x0 = cx[i] - k * cy[i];  // x(y) = x0 + k y
            int near = 0;  // a branch-free count first: most lines hold only their two candidates
            for (size_t m = 0; m < n; ++m) near += std::fabs(cx[m] - x0 - k * cy[m]) <= tol;
            if (near < p.min_dots) continue;
            on_line.clear();
            for (size_t m = 0; m < n; ++m)
                if (std::fabs(cx[m] - x0 - k * cy[m]) <= tol) on_line.push_back(m);
            std::sort(on_line.begin(), on_line.end(), [&](size_t a, size_t b) { return cy[a] < cy[b]; });
            // Dots along the road, each at least min_gap_m in range beyond the last counted (Z = fy h / (y - y_vp)):
            // bright specks bunched on one vehicle (lamps, trim) count once.
            int count = 0;
            float z_last = std::numeric_limits<float>::infinity();
            for (size_t m : on_line) {
                const float z = float(cam.fy * cam.height_m) / std::max(1.f, cy[m] - vp.y);
                if (z <= z_last - float(p.min_gap_m)) {
                    ++count;
                    z_last = z;
                }
            }
            if (count < p.min_dots) continue;
            for (size_t m : on_line) blobs[size_t(cand[m])].dot = true;
        }

    // The dots' bars join the marking points (a row where a marking point lies within kJoinPx keeps that one).
    const size_t n_before = points.size();
    for (size_t i = 0; i < bars.size(); ++i) {
        if (!bars[i].is_short || owner[i] < 0 || !blobs[size_t(owner[i])].dot) continue;
        const MarkingPoint &b = bars[i].p;
        const auto row = std::equal_range(points.begin(), points.begin() + long(n_before), b,
                                          [](const MarkingPoint &a, const MarkingPoint &c) { return a.y < c.y; });
        if (std::none_of(row.first, row.second, [&](const MarkingPoint &q) { return std::fabs(q.x - b.x) <= kJoinPx; }))
            points.push_back(b);
    }
    if (points.size() > n_before) std::sort(points.begin(), points.end(), row_order);
}

} // namespace hw
