#include "lanes/marking_filter.hpp"

#include <opencv2/core.hpp>

#include <algorithm>
#include <cmath>
#include <cstdint>
#include <stdexcept>

namespace hw {

namespace {

// Sub-pixel position of a peak from its two neighbours (parabola through l, c, r):
// offset = (l - r) / (2 (l - 2c + r)), in [-0.5, 0.5] for a true peak.
float peak_offset(int l, int c, int r) {
    const int den = l - 2 * c + r;
    if (den == 0) return 0.f;
    return std::clamp(0.5f * float(l - r) / float(den), -0.5f, 0.5f);
}

// Keeps the points that continue into the previous or next scanned row: within 1.5 px of where a
// line through the vanishing point would put them, plus |k| px per row for the slope uncertainty.
// The points dropped are appended to `dropped` when given.
void keep_runs(std::vector<MarkingPoint> &pts, const ScanBand &band, const HorizonPrior &hp,
               std::vector<MarkingPoint> *dropped) {
    const size_t n = pts.size();
    std::vector<char> keep(n, 0);
    size_t prev_lo = 0, prev_hi = 0;  // points of the previous scanned row: [prev_lo, prev_hi)
    size_t i = 0;
    while (i < n) {
        size_t j = i;
        while (j < n && pts[j].y == pts[i].y) ++j;  // this row: [i, j)
        if (prev_hi > prev_lo && pts[prev_lo].y == pts[i].y - float(band.step)) {
            for (size_t a = i; a < j; ++a) {
                const float k = std::min(kMaxMarkingSlope, std::fabs(pts[a].x - hp.vp_x) /
                                                        std::max(1.f, pts[a].y - (hp.row + hp.tol_px)));
                const float tol = 1.5f + k * float(band.step);
                for (size_t b = prev_lo; b < prev_hi; ++b)
                    if (std::fabs(pts[b].x - pts[a].x) <= tol) keep[a] = keep[b] = 1;
            }
        }
        prev_lo = i;
        prev_hi = j;
        i = j;
    }
    size_t o = 0;
    for (size_t a = 0; a < n; ++a)
        if (keep[a]) pts[o++] = pts[a];
        else if (dropped) dropped->push_back(pts[a]);
    pts.resize(o);
}

} // namespace

ScanBand scan_band(cv::Size size, const CameraParams &cam, const HorizonPrior &hp,
                   const MarkingFilterParams &p) {
    ScanBand b;
    const float top = row_at_range(cam, hp.row, float(p.max_range_m));
    b.y_top = std::clamp(int(std::ceil(top)), 0, size.height - 1);
    b.y_bottom = cam.hood_row(size.height) - 1;
    const int n = b.y_bottom - b.y_top + 1;
    b.step = n > 0 ? std::max(1, (n + p.max_scan_rows - 1) / p.max_scan_rows) : 1;
    return b;
}

void find_marking_points(const cv::Mat &gray, const ScanBand &band, const CameraParams &cam,
                         const HorizonPrior &hp, const MarkingFilterParams &p,
                         std::vector<MarkingPoint> &out, std::vector<MarkingPoint> *short_bars, bool single_image) {
    if (gray.empty() || gray.type() != CV_8UC1)
        throw std::invalid_argument("find_marking_points: expected a non-empty 8-bit gray image");
    if (band.y_top < 0 || band.y_bottom >= gray.rows || band.step < 1)
        throw std::invalid_argument("find_marking_points: scan band outside the image");
    out.clear();
    if (short_bars) short_bars->clear();
    // Rows of frames wider than the working width are averaged over blocks of `dec` pixels first:
    // the masks then see a marking as in a 640-wide frame, with less noise, at a fraction of the cost.
    const int dec = std::max(1, gray.cols / p.work_width_px);
    const int w = gray.cols / dec;
    if (w < 8) return;
    const float scale = float(dec);
    auto full_x = [&](float x) { return (x + 0.5f) * scale - 0.5f; };  // block centre in the frame

    std::vector<uint8_t> row_buf(size_t(w), 0);
    std::vector<float> rising, falling;
    std::vector<int> rising_g, falling_g;  // |response| of each edge
    const int t_min = int(std::ceil(p.min_edge_contrast));

    for (int y = band.y_top; y <= band.y_bottom; y += band.step) {
        const uint8_t *row = gray.ptr<uint8_t>(y);
        if (dec > 1) {
            uint8_t *o = row_buf.data();
            if (dec == 2) {  // the common case (1280 wide): no division
                for (int x = 0; x < w; ++x) o[x] = uint8_t((row[2 * x] + row[2 * x + 1] + 1) >> 1);
            } else {
                for (int x = 0; x < w; ++x) {
                    int sum = 0;
                    for (int i = 0; i < dec; ++i) sum += row[x * dec + i];
                    o[x] = uint8_t((sum + dec / 2) / dec);
                }
            }
            row = o;
        }
        // [-1 0 1] correlation: g(x) = I(x+1) - I(x-1); its negative is the [1 0 -1] response.
        // Row noise: the mean |g| of the row.
        int sum_abs = 0;
        for (int x = 1; x < w - 1; ++x) sum_abs += std::abs(int(row[x + 1]) - int(row[x - 1]));
        const int t_edge = std::max(t_min, int(std::ceil(p.noise_factor * sum_abs / (w - 2))));

        // Edges are the local maxima of each response above the threshold (one per edge); g is
        // computed on the fly in a window (g_prev, g_cur, g_next) around x.
        rising.clear();
        falling.clear();
        rising_g.clear();
        falling_g.clear();
        const unsigned band_t = unsigned(2 * t_edge - 1);
        int g_prev = int(row[2]) - int(row[0]), g_cur = int(row[3]) - int(row[1]);
        for (int x = 2; x < w - 2; ++x) {
            const int g_next = int(row[x + 2]) - int(row[x]);
            const int v = g_cur;
            if (unsigned(v + t_edge - 1) >= band_t) {  // |v| >= t_edge: rare
                if (v > 0) {
                    if (v >= g_prev && v > g_next) {
                        rising.push_back(float(x) + peak_offset(g_prev, v, g_next));
                        rising_g.push_back(v);
                    }
                } else if (v <= g_prev && v < g_next) {
                    falling.push_back(float(x) + peak_offset(-g_prev, -v, -g_next));
                    falling_g.push_back(-v);
                }
            }
            g_prev = g_cur;
            g_cur = g_next;
        }
        if (rising.empty() || falling.empty()) continue;

        // Marking width the flat-road model allows on this row, for any horizon within the prior's
        // tolerance: w = marking_m * fx (y - y_h) / (fy h); blur widens a thin bar by up to ~2 px.
        const float ppm_lo = px_per_m(cam, hp.row + hp.tol_px, float(y));
        const float ppm_hi = px_per_m(cam, hp.row - hp.tol_px, float(y));
        const float w_min = std::max(1.f, 0.7f * float(p.marking_min_m) * ppm_lo / scale);
        const float w_max = (1.2f * float(p.marking_max_m) * ppm_hi + 2.f) / scale;
        const float w_cross = (1.2f * float(p.cross_max_m) * ppm_hi + 2.f) / scale;
        // The bound along the row of a bar on a line of slope k (slant = sqrt(1 + k^2)). A stripe W wide along the
        // road crosses a row over fx W / Z px whatever its slope (x = x_vp + fx X / Z, Z fixed by the row); only the
        // blur across a slanted edge is slant times longer along the row (row_width_single, one image alone). Lane
        // tracking keeps the whole bound times slant, computed to the last bit as the slant-times bound
        // (headway eval --parts lanes).
        const bool row_width = single_image && p.row_width_single;
        auto row_bound = [&](double width_m, float w_slanted, float slant) {
            return row_width ? (1.2f * float(width_m) * ppm_hi + 2.f * slant) / scale : w_slanted * slant;
        };
        const float dy_vp = std::max(1.f, float(y) - (hp.row + hp.tol_px));

        // Pair each dark-to-bright edge with the nearest bright-to-dark edge after it that closes a
        // valid bar (width, contrast). Worn or textured paint has weaker edges inside the bar; they
        // are crossed, not taken as the bar's end (the bar is judged on its mean against both sides).
        // A rising edge inside an accepted bar starts no second bar.
        size_t j0 = 0;
        float bar_end = -1.f;
        for (size_t i = 0; i < rising.size(); ++i) {
            const float r = rising[i];
            if (r < bar_end) continue;
            bool short_kept = false;  // a bar narrower than w_min from this edge went to short_bars
            while (j0 < falling.size() && falling[j0] <= r) ++j0;
            if (j0 == falling.size()) break;
            const float w_far = w_max * std::sqrt(1.f + kMaxMarkingSlope * kMaxMarkingSlope);  // widest at any slant
            for (size_t j = j0; j < falling.size() && falling[j] - r <= w_far; ++j) {
                const float f = falling[j];
                // k = dx/dy of the line from the vanishing point through the bar (row_bound above).
                const float k = std::min(kMaxMarkingSlope, std::fabs(full_x(0.5f * (r + f)) - hp.vp_x) / dy_vp);
                const float slant = std::sqrt(1.f + k * k);
                if (f - r > row_bound(p.marking_max_m, w_max, slant)) continue;
                // Narrower than a marking may be: a Botts' dot or a speck, judged by dot_markings (short_bars).
                const bool narrow = f - r < w_min;
                if (narrow && !short_bars) continue;
                // Bar: pixels strictly between the edges; sides: one pixel beyond each edge pixel.
                int a = int(std::floor(r)) + 1, b = int(std::ceil(f)) - 1;
                if (b < a) a = b = int(std::lround(0.5f * (r + f)));
                int sum = 0, lowest = 255;
                for (int x = a; x <= b; ++x) {
                    sum += row[x];
                    lowest = std::min(lowest, int(row[x]));
                }
                const float inside = float(sum) / float(b - a + 1);
                const int xl = std::max(0, int(std::floor(r)) - 1);
                const int xr = std::min(w - 1, int(std::ceil(f)) + 1);
                const float side = float(std::max(row[xl], row[xr]));
                const float contrast = inside - side;
                if (contrast < float(p.min_bar_contrast) || contrast < float(p.min_bar_ratio) * side) continue;
                // Across inner edges (texture of worn paint) the bar must stay brighter than its sides
                // everywhere, and every inner edge must be weaker than both of the bar's own edges: two
                // markings, or a marking and a bright patch, have road (a dip) or strong edges between.
                const int own = std::min(rising_g[i], falling_g[j]);
                bool inner_weak = true;
                for (size_t q = j0; q < j && inner_weak; ++q) inner_weak = falling_g[q] < own;
                for (size_t q = i + 1; q < rising.size() && rising[q] < f && inner_weak; ++q)
                    inner_weak = rising_g[q] < own;
                const bool crosses = j > j0 || (i + 1 < rising.size() && rising[i + 1] < f);
                if (crosses && (!p.cross_inner_edges || !inner_weak || float(lowest) <= side)) continue;
                // ... and be one painted line wide: a wide bright patch with texture inside (concrete between
                // two seams, a tyre-polished strip) is not worn paint.
                if (crosses && f - r > row_bound(p.cross_max_m, w_cross, slant)) continue;
                if (narrow) {  // a wider bar from this edge may still be a marking: look on
                    if (!short_kept)
                        short_bars->push_back({full_x(0.5f * (r + f)), float(y), contrast, (f - r) * scale});
                    short_kept = true;
                    continue;
                }
                if (short_kept) short_bars->pop_back();  // the edge starts a marking, not a dot
                out.push_back({full_x(0.5f * (r + f)), float(y), contrast, (f - r) * scale});
                bar_end = f;
                break;
            }
        }
    }
    if (p.min_run_rows >= 2) keep_runs(out, band, hp, short_bars);
    if (short_bars)  // by row, then column, as the marking points
        std::sort(short_bars->begin(), short_bars->end(), row_order);
}

} // namespace hw
