#include "cues/shadow.hpp"

#include "base/sections.hpp"
#include "cues/edge_projection.hpp"

#include <opencv2/imgproc.hpp>

#include <algorithm>
#include <array>
#include <cmath>

namespace hw {

namespace {

// Road gray level (median) per cell: level_bands row bands x level_columns cells across the road
// interval of each row. A median ignores the vehicles and shadows inside a cell as long as they
// cover less than half of it.
class RoadLevels {
public:
    RoadLevels(const cv::Mat &gray, const RoadPrior &road, int bands, int columns)
        : road_(road), bands_(bands), columns_(columns), level_(size_t(bands * columns), 0.f) {
        std::vector<std::array<int, 256>> hist(level_.size());
        std::array<int, 256> all{};
        for (auto &h : hist) h.fill(0);
        // Every second row and column is plenty for a median and halves the cost.
        for (int y = road.y_top; y < road.y_bottom; y += 2) {
            const int xl = road.left(y), xr = road.right(y);
            if (xl > xr) continue;
            const uint8_t *row = gray.ptr<uint8_t>(y);
            for (int x = xl; x <= xr; x += 2) {
                hist[cell(y, x, xl, xr)][row[x]]++;
                all[row[x]]++;
            }
        }
        const float global = median(all, 128.f);
        for (size_t i = 0; i < hist.size(); ++i) level_[i] = median(hist[i], global);
    }

    // Cell index of pixel (x, y) whose row interval is [xl, xr].
    size_t cell(int y, int x, int xl, int xr) const {
        return band_cell(y, std::min(columns_ - 1, (x - xl) * columns_ / (xr - xl + 1)));
    }
    // Cell index of row y and column cell `col`.
    size_t band_cell(int y, int col) const {
        const int band = std::min(bands_ - 1, (y - road_.y_top) * bands_ / (road_.y_bottom - road_.y_top));
        return size_t(band * columns_ + col);
    }
    float level(size_t cell) const { return level_[cell]; }

private:
    // Median of a histogram; `fallback` for a cell with too few samples to say.
    static float median(const std::array<int, 256> &h, float fallback) {
        int n = 0;
        for (int c : h) n += c;
        if (n < 32) return fallback;
        int acc = 0;
        for (int v = 0; v < 256; ++v)
            if ((acc += h[v]) * 2 >= n) return float(v);
        return fallback;
    }

    const RoadPrior &road_;
    int bands_, columns_;
    std::vector<float> level_;
};

// One horizontal run of shadow-edge pixels, and a merged group of runs (one candidate edge).
struct Run {
    int y, x1, x2;       // row, inclusive column range
    float step_sum;      // sum over its pixels of the step / road level
    int n;               // edge pixels in it
};

struct Edge {
    int x1, x2;          // inclusive column range (union of its runs)
    int y_bottom, y_top; // lowest and highest row of its runs
    float step_sum;
    int n;
    float road_gray;
    float bottom;        // sub-pixel row of the road/shadow boundary
    int width() const { return x2 - x1 + 1; }
};

int overlap(int a1, int a2, int b1, int b2) { return std::min(a2, b2) - std::max(a1, b1) + 1; }

// Runs of shadow-edge pixels in row y: Sobel step Gy(x) = (I(y+1) - I(y-1)) smoothed along x, at
// least thr.grad, with I(y-1) at most thr.dark; gaps of up to gap_px pixels are bridged.
void row_runs(const cv::Mat &gray, const short *gy, int y, int xl, int xr, const RoadLevels &levels,
              const std::vector<ShadowThresholds> &thr, const ShadowParams &p, std::vector<Run> &out) {
    const uint8_t *above = gray.ptr<uint8_t>(y - 1);
    Run run{y, -1, -1, 0.f, 0};
    int last = -1000000;
    auto close = [&]() {
        if (run.x1 >= 0 && run.x2 - run.x1 + 1 >= p.min_run_px) out.push_back(run);
        run = Run{y, -1, -1, 0.f, 0};
    };
    const int len = xr - xl + 1;
    for (int col = 0; col < p.level_columns; ++col) {
        // The cells of this row, one threshold pair each.
        const int xa = xl + col * len / p.level_columns, xb = xl + (col + 1) * len / p.level_columns;
        if (xa >= xb) continue;
        const size_t c = levels.band_cell(y, col);
        const int grad = thr[c].grad, dark = thr[c].dark;
        const float inv = 1.f / (4.f * std::max(1.f, levels.level(c)));
        for (int x = xa; x < xb; ++x) {
            if (gy[x] < grad || above[x] > dark) continue;
            if (x - last > p.gap_px + 1) close();
            if (run.x1 < 0) run.x1 = x;
            run.x2 = x;
            run.step_sum += gy[x] * inv;
            run.n++;
            last = x;
        }
    }
    close();
}

// Merges runs (given bottom-up) into edges: a run joins the edge it overlaps most whose highest
// row is at most merge_rows above it (thesis: "edges whose y differ by <= 2 px are combined").
std::vector<Edge> merge_runs(const std::vector<Run> &runs, int merge_rows) {
    std::vector<Edge> edges;
    for (const Run &r : runs) {
        Edge *best = nullptr;
        int best_ov = 0;
        for (Edge &e : edges) {
            if (e.y_top - r.y > merge_rows) continue;
            const int ov = overlap(r.x1, r.x2, e.x1, e.x2);
            if (ov > best_ov) { best_ov = ov; best = &e; }
        }
        if (!best) {
            edges.push_back({r.x1, r.x2, r.y, r.y, r.step_sum, r.n, 0.f, float(r.y)});
            continue;
        }
        best->x1 = std::min(best->x1, r.x1);
        best->x2 = std::max(best->x2, r.x2);
        best->y_top = std::min(best->y_top, r.y);
        best->step_sum += r.step_sum;
        best->n += r.n;
    }
    return edges;
}

// Joins edges at the same height (bottom rows within merge_rows) separated by a gap of at most
// join_gap_frac expected widths: the shadow under a vehicle often breaks into pieces at the wheels
// or where a bright axle or exhaust interrupts it.
void join_pieces(std::vector<Edge> &edges, const RoadPrior &road, const ShadowParams &p) {
    std::sort(edges.begin(), edges.end(), [](const Edge &a, const Edge &b) { return a.x1 < b.x1; });
    for (bool changed = true; changed;) {
        changed = false;
        for (size_t i = 0; i < edges.size() && !changed; ++i)
            for (size_t j = i + 1; j < edges.size() && !changed; ++j) {
                Edge &a = edges[i], &b = edges[j];
                if (std::abs(a.y_bottom - b.y_bottom) > p.merge_rows) continue;
                const int gap = -overlap(a.x1, a.x2, b.x1, b.x2);
                const float w_exp = road.expected_width(std::max(a.y_bottom, b.y_bottom));
                if (gap > p.join_gap_frac * w_exp) continue;
                a.x1 = std::min(a.x1, b.x1); a.x2 = std::max(a.x2, b.x2);
                a.y_bottom = std::max(a.y_bottom, b.y_bottom); a.y_top = std::min(a.y_top, b.y_top);
                a.step_sum += b.step_sum; a.n += b.n;
                edges.erase(edges.begin() + long(j));
                changed = true;
            }
    }
}

// Sub-pixel boundary row of an edge: the peak of its column-averaged Gy over the rows around its
// lowest row (the step between a dark row k and a bright row k+1 peaks at k + 0.5).
float boundary_row(const cv::Mat &gy, int row0, int col0, const Edge &e) {
    const int lo = std::max(row0, e.y_bottom - 3), hi = std::min(row0 + gy.rows - 1, e.y_bottom + 1);
    std::vector<float> v;
    for (int y = lo; y <= hi; ++y) {
        const short *g = gy.ptr<short>(y - row0) - col0;
        float s = 0.f;
        for (int x = e.x1; x <= e.x2; ++x) s += g[x];
        v.push_back(s);
    }
    return float(lo) + peak_position(v, argmax(v, 0, int(v.size())));
}

// Share of dark pixels (at most `dark`) just above row y over columns [xa, xb] (clipped to the
// scanned interval of that row); -1 when nothing of the range is scanned.
float dark_share(const cv::Mat &gray, const RoadPrior &road, int y, int xa, int xb, int dark) {
    int n = 0, d = 0;
    for (int r = std::max(road.y_top, y - 2); r <= y - 1; ++r) {
        const uint8_t *row = gray.ptr<uint8_t>(r);
        for (int x = std::max(xa, road.left(r)); x <= std::min(xb, road.right(r)); ++x, ++n) d += row[x] <= dark;
    }
    return n ? float(d) / float(n) : -1.f;
}

// A vehicle's shadow ends with the vehicle: beside it lies lit road. The edge of a shadow across the
// road (an overpass, a row of trees) only breaks where lane markings or vehicles interrupt it, and
// its dark side goes on past the ends of each piece. Such a piece is no vehicle's bottom edge.
bool part_of_band(const cv::Mat &gray, const RoadPrior &road, const Edge &e, const ShadowParams &p) {
    const int reach = std::max(3, int(0.5f * road.expected_width(e.y_bottom)));
    const int dark = int(p.edge.dark_rel * e.road_gray);
    const float left = dark_share(gray, road, e.y_bottom, e.x1 - reach, e.x1 - 1, dark);
    const float right = dark_share(gray, road, e.y_bottom, e.x2 + 1, e.x2 + reach, dark);
    if (left < 0.f && right < 0.f) return false;  // nothing scanned beside it: cannot tell
    // Unscanned on one side (image or road border): the band may go on there.
    return (left < 0.f || left >= p.band_dark_frac) && (right < 0.f || right >= p.band_dark_frac);
}

// What lies just above a shadow edge in one column, seen from below: up from the edge's dark row over the dark
// band (at most 0.3 expected widths), one blurred row skipped, the mean gray of `rows` rows.
enum class Above : char {
    road,     // within beside_rel of the road level: lit road (a shadow cast beside a vehicle lies on the road)
    vehicle,  // dark all the way up: a tyre, a dark body
    none,     // no shadow in this column (a gap between the edge's runs, a lane marking across it)
    bright,   // brighter than lit road: a lane marking, a light bumper, lights
    other,    // darker than lit road, not dark: a vehicle's body
};

Above above_shadow(const cv::Mat &gray, const Edge &e, int x, int rows, int max_dark, const ShadowParams &p) {
    const int dark = int(p.edge.dark_rel * e.road_gray);
    // The band's lowest dark row in this column: the edge's runs lie on rows up to merge_rows apart.
    int y = e.y_bottom - 1;
    while (y > e.y_bottom - 2 - p.merge_rows && y > 0 && gray.at<uint8_t>(y, x) > dark) --y;
    if (gray.at<uint8_t>(y, x) > dark) return Above::none;
    while (y > e.y_bottom - 1 - max_dark && y > 0 && gray.at<uint8_t>(y, x) <= dark) --y;
    if (y <= e.y_bottom - 1 - max_dark) return Above::vehicle;
    y -= 1;
    if (y - rows + 1 < 0) return Above::vehicle;
    float sum = 0.f;
    for (int r = y; r > y - rows; --r) sum += gray.at<uint8_t>(r, x);
    const float rel = sum / float(rows) / std::max(1.f, e.road_gray) - 1.f;
    return rel > p.beside_rel ? Above::bright : rel >= -p.beside_rel ? Above::road : Above::other;
}

// Columns of a stretch with lit road above, from the end `from` inwards (step +-1): it starts within `lead`
// columns of the end, past no vehicle column (only lit road, brighter columns or columns without a shadow:
// the lane marking where the cast shadow often ends), goes on over gaps of at most `max_gap` columns (brighter
// ones are no gap: a marking above the cast shadow) and ends at the vehicle (a dark or body column follows);
// the deepest such stretch. 0 when there is none.
int road_stretch(const std::vector<Above> &col, int from, int step, int lead, int max_gap) {
    const int n = int(col.size());
    int depth = 0;
    for (int s = from; std::abs(s - from) < lead && s >= 0 && s < n; s += step) {
        const Above c = col[size_t(s)];
        if (c == Above::vehicle || c == Above::other) break;
        if (c != Above::road) continue;
        int last = s;
        for (int i = s, gap = 0; i >= 0 && i < n && gap <= max_gap; i += step) {
            const Above ci = col[size_t(i)];
            gap = ci == Above::road ? 0 : ci == Above::bright ? gap : gap + 1;
            if (ci == Above::road) last = i;
        }
        // It must end at the vehicle (a dark or body column right after it) and be mostly lit road where
        // no marking lies above it.
        bool at_vehicle = false;
        for (int i = last + step; std::abs(i - last) <= max_gap + 1 && i >= 0 && i < n; i += step)
            at_vehicle = at_vehicle || col[size_t(i)] == Above::vehicle || col[size_t(i)] == Above::other;
        int road = 0, unlit = 0;
        for (int i = s; i != last + step; i += step) {
            road += col[size_t(i)] == Above::road;
            unlit += col[size_t(i)] != Above::road && col[size_t(i)] != Above::bright;
        }
        if (at_vehicle && 3 * road >= 2 * (road + unlit)) depth = std::max(depth, std::abs(last - from) + 1);
    }
    return depth;
}

// A low sun casts a vehicle's shadow past one of its sides onto the road, where it often ends only at the
// next lane marking, and verification took the marking for that side (tme08). The stretch at one end of the
// edge with lit road above it (road_stretch, at least beside_min_frac expected widths) is cut off when at least
// beside_rest_frac of them remain under the vehicle; the sun
// shines under the vehicle's other side, where the shadow begins inside the vehicle, so the edge then reaches
// at least beside_reach expected widths from the cut towards the sun. Lit road at both ends is no shadow cast
// to one side (a vehicle as gray as the road): the edge is left whole, as is a long one (beside_max_ratio).
void cut_shadow_beside(const cv::Mat &gray, Edge &e, float w_exp, const ShadowParams &p) {
    if (!(p.beside_rel > 0.0) || e.width() > p.beside_max_ratio * w_exp) return;
    const int rows = std::max(2, int(std::lround(p.beside_rows_frac * w_exp)));
    const int max_dark = std::max(3, int(std::lround(0.3f * w_exp)));
    const int n = e.width(), lead = std::max(2, int(std::lround(0.2f * w_exp))), max_gap = p.merge_rows + 1;
    std::vector<Above> col(size_t(n), Above::vehicle);
    for (int x = e.x1; x <= e.x2; ++x) col[size_t(x - e.x1)] = above_shadow(gray, e, x, rows, max_dark, p);
    const float min_cut = float(p.beside_min_frac) * w_exp;
    int l = road_stretch(col, 0, 1, lead, max_gap), r = road_stretch(col, n - 1, -1, lead, max_gap);
    l = l >= min_cut ? l : 0;
    r = r >= min_cut ? r : 0;
    if ((l > 0) == (r > 0) || n - l - r < p.beside_rest_frac * w_exp) return;
    // Above the rest, the vehicle: lit road there too is a vehicle as gray as the road, not a cast shadow.
    int road_rest = 0;
    for (int i = l; i < n - r; ++i) road_rest += col[size_t(i)] == Above::road;
    if (road_rest > 0.2 * (n - l - r)) return;
    const int reach = int(std::lround(p.beside_reach * w_exp));
    if (r > 0) {
        e.x2 -= r;
        e.x1 = std::max(0, std::min(e.x1, e.x2 - reach + 1));
    } else {
        e.x1 += l;
        e.x2 = std::min(gray.cols - 1, std::max(e.x2, e.x1 + reach - 1));
    }
}

// One bottom edge per vehicle: lowest first; an edge above a kept one, overlapping it by half the
// shorter of the two and within reduce_height_ratio vehicle widths above it (the vehicle's width:
// the edge's own, but at most 1.5 expected widths for a long shadow), lies on the same vehicle.
std::vector<Edge> one_per_vehicle(std::vector<Edge> edges, const RoadPrior &road, const ShadowParams &p) {
    std::sort(edges.begin(), edges.end(), [](const Edge &a, const Edge &b) {
        return a.y_bottom != b.y_bottom ? a.y_bottom > b.y_bottom : a.width() > b.width();
    });
    std::vector<Edge> bottoms;
    for (const Edge &e : edges) {
        bool same = false;
        for (const Edge &k : bottoms) {
            const float vehicle_w = std::min(float(k.width()), 1.5f * road.expected_width(k.y_bottom));
            same = same || (overlap(e.x1, e.x2, k.x1, k.x2) * 2 >= std::min(e.width(), k.width()) &&
                            k.y_bottom - e.y_bottom <= p.reduce_height_ratio * vehicle_w);
        }
        if (!same) bottoms.push_back(e);
    }
    return bottoms;
}

} // namespace

ShadowThresholds shadow_thresholds(float road_gray, const ShadowEdgeParams &p) {
    // A step of s gray levels between the rows above and below gives a 3x3 Sobel response of 4 s.
    const double step = std::max(p.min_step_gray, p.grad_rel * road_gray);
    return {int(std::ceil(4.0 * step)), int(std::floor(p.dark_rel * road_gray))};
}

std::vector<ShadowHypothesis> shadow_hypotheses(const cv::Mat &gray, const LaneModel &lanes,
                                          const CameraParams &cam, const ShadowParams &p) {
    CV_Assert(!gray.empty() && gray.type() == CV_8UC1);
    const RoadPrior road = make_road_prior(gray.size(), lanes, cam, p.road);
    if (road.empty()) return {};
    int xmin = gray.cols, xmax = -1;
    for (int y = road.y_top; y < road.y_bottom; ++y)
        if (road.left(y) <= road.right(y)) {
            xmin = std::min(xmin, road.left(y));
            xmax = std::max(xmax, road.right(y));
        }
    if (xmax < xmin) return {};

    const RoadLevels levels(gray, road, p.level_bands, p.level_columns);
    std::vector<ShadowThresholds> thr;
    for (size_t c = 0; c < size_t(p.level_bands * p.level_columns); ++c)
        thr.push_back(shadow_thresholds(levels.level(c), p.edge));

    // Gy = d/dy of the scanned rows (positive where the road below is brighter than above).
    const cv::Rect band(xmin, road.y_top, xmax - xmin + 1, road.y_bottom - road.y_top);
    cv::Mat gy;
    cv::Sobel(gray(band), gy, CV_16S, 0, 1, 3);

    // Bottom-up scan (thesis): runs are produced lowest row first.
    std::vector<Run> runs;
    for (int y = road.y_bottom - 1; y >= road.y_top; --y) {
        const int xl = road.left(y), xr = road.right(y);
        if (xl > xr) continue;
        row_runs(gray, gy.ptr<short>(y - road.y_top) - xmin, y, xl, xr, levels, thr, p, runs);
    }
    std::vector<Edge> edges = merge_runs(runs, p.merge_rows);
    join_pieces(edges, road, p);

    // Width against the vehicle expected at the edge's row.
    std::vector<Edge> kept;
    for (Edge &e : edges) {
        const float w_exp = road.expected_width(e.y_bottom);
        if (!(w_exp > 0.f)) continue;
        if (e.width() < p.min_width_frac * w_exp) continue;
        if (e.width() > p.max_width_ratio * w_exp) continue;  // a dark band across the road
        e.road_gray = levels.level(levels.cell(e.y_bottom, (e.x1 + e.x2) / 2, road.left(e.y_bottom),
                                               road.right(e.y_bottom)));
        if (part_of_band(gray, road, e, p)) continue;
        cut_shadow_beside(gray, e, w_exp, p);
        e.bottom = boundary_row(gy, road.y_top, xmin, e);
        kept.push_back(e);
    }

    const std::vector<Edge> bottoms = one_per_vehicle(kept, road, p);

    std::vector<ShadowHypothesis> out;
    for (const Edge &e : bottoms) {
        ShadowHypothesis h;
        const float bottom = e.bottom, w = float(e.width()), height = 0.5f * w;
        h.box = cv::Rect2f(float(e.x1), bottom - height, w, height);
        h.strength = std::min(1.f, e.step_sum / float(std::max(1, e.n)));
        h.expected_width_px = road.expected_width(e.y_bottom);
        h.road_gray = e.road_gray;
        out.push_back(h);
    }
    std::stable_sort(out.begin(), out.end(),
                     [](const ShadowHypothesis &a, const ShadowHypothesis &b) { return a.strength > b.strength; });
    if (int(out.size()) > p.max_hypotheses) out.resize(size_t(p.max_hypotheses));
    return out;
}

namespace {

// Its section, read by the shadow detector and the Kalman tracker's ROI search (base/sections.hpp).
const bool registered = register_section<ShadowEdgeParams>("shadow_edge");

} // namespace

} // namespace hw
