#include "road/lane_features.hpp"

#include <opencv2/imgproc.hpp>
#include <opencv2/video/tracking.hpp>

#include <emmintrin.h>

#include <algorithm>
#include <cmath>
#include <cstring>

namespace hw {

void LaneFeatureParams::bind(ParamMap &m) {
    m.add("marking_width_m", marking_width_m, 0.05, 1.0,
          "m; painted line width the row filter is sized for (0.10-0.15 m on motorways)");
    m.add("t_factor", t_factor, 0.5, 5.0,
          "marking widths; the filter's neighbour distance t(j); 1.5 lets both neighbours of any pixel "
          "on a marking fall off it, also for markings slanted by perspective");
    m.add("t_min_px", t_min_px, 1, 50, "px; smallest t, near the vanishing point where markings are 1-2 px wide");
    m.add("response_min", response_min, 1.0, 510.0,
          "gray levels; eq. 1 response kept; the response is twice the margin over the brighter neighbour, so "
          "40 keeps markings 20 levels brighter than the road around them and drops most asphalt grain");
    m.add("min_run_frac", min_run_frac, 0.0, 1.0,
          "marking widths; a run of response narrower than this is a texture speck, not a marking");
    m.add("max_range_m", max_range_m, 5.0, 500.0,
          "m; farthest road range filtered; beyond 50 m markings are too thin and too close to the horizon to "
          "constrain the homography (the paper names features near the horizon as unreliable)");
    m.add("hough_threshold", hough_threshold, 1, 1000,
          "votes; accumulator threshold of the probabilistic Hough transform; the response is thinned to one pixel "
          "per row, so a far dash (~8 rows) gives about 8 votes");
    m.add("hough_min_length_px", hough_min_length_px, 2, 1000, "px; shortest Hough segment; a dash 50 m ahead is ~8 px long");
    m.add("hough_max_gap_px", hough_max_gap_px, 0, 100, "px; gap bridged inside one Hough segment");
    m.add("min_angle_deg", min_angle_deg, 0.0, 90.0,
          "deg from horizontal; flatter segments are vehicle bottoms or shadows; 12 still keeps the outer road "
          "edges of a three-lane road (about 14 deg at 640x480)");
    m.add("vp_tol_px", vp_tol_px, 0.0, 10000.0,
          "px; a Hough segment whose line passes farther than this from the road's vanishing point is not a "
          "marking (vehicle edges, shadows, texture); 40 allows for curves and yaw shake; 0 disables");
    m.add("cluster_tol_px", cluster_tol_px, 0.5, 100.0,
          "px; a segment joins a marking when both its ends lie this close to the marking's line (plus one "
          "marking width at that row)");
    m.add("max_markings", max_markings, 1, 32, "count; markings kept, most Hough support first");
    m.add("grow_across", grow_across, 0.5, 20.0,
          "marking widths; half-width of the search region across the marking, enough for the dash corners and "
          "the mean segment's error; the Harris cost grows with it");
    m.add("grow_min_px", grow_min_px, 1, 100, "px; smallest half-width of a search region (far rows)");
    m.add("grow_max_px", grow_max_px, 1, 1000,
          "px; largest half-width of a search region; near the camera a marking is ~30 px wide and its dash ends "
          "lie within 15 px of its centre line, so 20 px holds them while bounding the Harris cost");
    m.add("max_corners", max_corners, 4, 5000,
          "count; Harris corners at most (strongest first); bounds the Lucas-Kanade cost; 50 leave the DLT "
          "over-determined several times over");
    m.add("harris_quality", harris_quality, 1e-6, 1.0,
          "fraction of the strongest Harris response a corner must reach; tiny, as the response grows with the "
          "fourth power of contrast (docs/tracking.md)");
    m.add("harris_k", harris_k, 0.01, 0.25, "Harris detector free parameter (det - k trace^2)");
    m.add("min_corner_distance_px", min_corner_distance_px, 1, 100, "px; corners closer than this are one");
    m.add("lk_window_px", lk_window_px, 5, 101,
          "px; Lucas-Kanade window side; 11 holds a dash corner, and the pre-warp leaves no scale change to average");
    m.add("lk_levels", lk_levels, 0, 6,
          "pyramid levels above the base; the patches are pre-warped with the prediction, so 1 covers what it "
          "misses (shake, speed changes; the far points of a first frame without prediction)");
    m.add("lk_patch_px", lk_patch_px, 9, 301,
          "px; side of the pre-warped patch around each corner; the window plus twice the largest prediction "
          "error followed (31: +-10 px)");
    m.add("lk_search_patch_px", lk_search_patch_px, 9, 1001,
          "px; patch side while there is no prediction (first frames, no ego speed): a road point 4 m ahead moves "
          "~60 px per frame at 100 km/h and 30 fps");
    m.add("lk_search_levels", lk_search_levels, 0, 6, "pyramid levels while there is no prediction");
    m.add("fb_max_px", fb_max_px, 0.05, 10.0,
          "px; largest forward-backward error of a kept correspondence; a point sliding along a marking or "
          "hidden by a vehicle does not come back");
}

cv::Range lane_feature_rows(int height, float horizon_row, const CameraParams &cam, const LaneFeatureParams &p) {
    // Row of range Z: y = y_h + fy h / Z.
    const int top = int(std::ceil(horizon_row + cam.fy * cam.height_m / p.max_range_m));
    const int y0 = std::clamp(top, 0, height);
    return cv::Range(y0, height);
}

namespace {

// Runs [begin, end) of the 255 bytes of a 0/255 row (memchr scans the empty stretches fast).
void row_runs(const uint8_t *m, int W, std::vector<cv::Vec2i> &runs) {
    runs.clear();
    int x = 0;
    while (x < W) {
        const void *b = std::memchr(m + x, 255, size_t(W - x));
        if (!b) break;
        const int start = int(static_cast<const uint8_t *>(b) - m);
        const void *e = std::memchr(m + start, 0, size_t(W - start));
        x = e ? int(static_cast<const uint8_t *>(e) - m) : W;
        runs.push_back({start, x});
    }
}

} // namespace

// An AVX2 clone beside the baseline one (integer arithmetic: the same response).
__attribute__((target_clones("avx2", "default")))
void marking_response(const cv::Mat &gray, cv::Range rows, float horizon_row, const CameraParams &cam,
                      const LaneFeatureParams &p, cv::Mat &binary) {
    CV_Assert(gray.type() == CV_8UC1);
    CV_Assert(rows.start >= 0 && rows.end <= gray.rows);
    binary.create(gray.size(), CV_8UC1);
    binary.setTo(0);
    const int W = gray.cols;
    const int thr = int(std::ceil(p.response_min));
    std::vector<uint8_t> on(size_t(W), 0);
    std::vector<cv::Vec2i> runs;
    for (int j = rows.start; j < rows.end; ++j) {
        // Marking width in px at this row: fx / Z * w_m with Z = fy h / (j - y_h).
        const double width = p.marking_width_m * std::max(0.0, cam.fx * (j - horizon_row) / (cam.fy * cam.height_m));
        const int t = std::max(p.t_min_px, int(std::lround(p.t_factor * width)));
        if (2 * t >= W) continue;
        const int min_run = std::max(1, int(std::lround(p.min_run_frac * width)));
        const uint8_t *x = gray.ptr<uint8_t>(j);
        uint8_t *y = binary.ptr<uint8_t>(j);
        // eq. 1: y_i = 2 x_i - (x_{i-t} + x_{i+t}) - |x_{i-t} - x_{i+t}|, thresholded to 0/255 (a plain loop
        // the compiler vectorises), then each run reduced to its centre (row_runs skips the empty stretches).
        for (int i = t; i < W - t; ++i) {
            const int l = x[i - t], r = x[i + t];
            on[i] = uint8_t(-int(2 * x[i] - (l + r) - std::abs(l - r) >= thr));
        }
        row_runs(on.data() + t, W - 2 * t, runs);
        for (const auto &run : runs)
            if (run[1] - run[0] >= min_run) y[t + (run[0] + run[1] - 1) / 2] = 255;
    }
}

namespace {

// Distance of p from the infinite line through a and b.
float line_distance(cv::Point2f a, cv::Point2f b, cv::Point2f p) {
    const cv::Point2f d = b - a;
    const float n = std::hypot(d.x, d.y);
    return n < 1e-6f ? float(cv::norm(p - a)) : std::fabs(d.x * (p.y - a.y) - d.y * (p.x - a.x)) / n;
}

struct Segment {
    cv::Point2f lower, upper;
    float length;
};

} // namespace

std::vector<MarkingSegment> marking_segments(const cv::Mat &binary, cv::Range rows, cv::Point2f vp,
                                             const CameraParams &cam, const LaneFeatureParams &p) {
    const float horizon_row = vp.y;
    std::vector<MarkingSegment> out;
    if (rows.size() < 2) return out;
    std::vector<cv::Vec4i> lines;
    // 2 px x 2 deg cells: the accumulator (cleared on every call) is a quarter of the 1 px x 1 deg one;
    // the segment ends come from the pixels walked, not from the cell.
    cv::HoughLinesP(binary.rowRange(rows), lines, 2.0, 2.0 * CV_PI / 180.0, p.hough_threshold, p.hough_min_length_px,
                    p.hough_max_gap_px);
    const float tan_min = float(std::tan(p.min_angle_deg * CV_PI / 180.0));
    std::vector<Segment> segs;
    for (const auto &l : lines) {
        cv::Point2f a(float(l[0]), float(l[1] + rows.start)), b(float(l[2]), float(l[3] + rows.start));
        if (std::fabs(b.y - a.y) < tan_min * std::fabs(b.x - a.x)) continue;  // too flat
        if (a.y < b.y) std::swap(a, b);
        if (p.vp_tol_px > 0 && line_distance(a, b, vp) > p.vp_tol_px) continue;  // not toward the vanishing point
        segs.push_back({a, b, float(cv::norm(a - b))});
    }
    std::sort(segs.begin(), segs.end(), [](const Segment &a, const Segment &b) { return a.length > b.length; });

    // Marking width in px at row y (0 above the horizon).
    auto width_px = [&](float y) {
        return float(std::max(0.0, p.marking_width_m * cam.fx * (y - horizon_row) / (cam.fy * cam.height_m)));
    };
    struct Cluster {
        Segment seed;
        std::vector<int> members;
        float support = 0.f;
    };
    std::vector<Cluster> clusters;
    for (int s = 0; s < int(segs.size()); ++s) {
        const Segment &g = segs[s];
        bool joined = false;
        for (auto &c : clusters) {
            const float tl = float(p.cluster_tol_px) + width_px(g.lower.y);
            const float tu = float(p.cluster_tol_px) + width_px(g.upper.y);
            if (line_distance(c.seed.lower, c.seed.upper, g.lower) < tl &&
                line_distance(c.seed.lower, c.seed.upper, g.upper) < tu) {
                c.members.push_back(s);
                c.support += g.length;
                joined = true;
                break;
            }
        }
        if (!joined) clusters.push_back({g, {s}, g.length});
    }
    std::sort(clusters.begin(), clusters.end(), [](const Cluster &a, const Cluster &b) { return a.support > b.support; });
    if (int(clusters.size()) > p.max_markings) clusters.resize(size_t(p.max_markings));

    const float y_min = float(rows.start), y_max = float(rows.end - 1);
    for (const auto &c : clusters) {
        MarkingSegment m;
        // s_i = (1/S_i) sum_j (p_l_ij, p_u_ij): the mean segment of the marking.
        for (int s : c.members) {
            m.lower += segs[s].lower;
            m.upper += segs[s].upper;
        }
        m.lower *= 1.f / float(c.members.size());
        m.upper *= 1.f / float(c.members.size());
        m.segments = int(c.members.size());
        // The region follows the mean segment's line x(y) = x_l + k (y - y_l) over all rows of the band.
        const float dy = m.lower.y - m.upper.y;
        if (dy < 1.f) continue;
        const float k = (m.upper.x - m.lower.x) / (m.upper.y - m.lower.y);
        const float yt = y_min, yb = y_max;
        const float stretch = std::sqrt(1.f + k * k);  // horizontal width of a slanted band
        auto half = [&](float y) {
            return stretch * std::clamp(float(p.grow_across) * width_px(y), float(p.grow_min_px), float(p.grow_max_px));
        };
        auto x_at = [&](float y) { return m.lower.x + k * (y - m.lower.y); };
        m.region = {cv::Point(cvRound(x_at(yt) - half(yt)), cvRound(yt)), cv::Point(cvRound(x_at(yt) + half(yt)), cvRound(yt)),
                    cv::Point(cvRound(x_at(yb) + half(yb)), cvRound(yb)), cv::Point(cvRound(x_at(yb) - half(yb)), cvRound(yb))};
        out.push_back(std::move(m));
    }
    return out;
}

namespace {

// Union of the runs of rows [r0, r1) of `rows`, each widened by `pad` and clipped to [lo, hi).
void union_runs(const std::vector<std::vector<cv::Vec2i>> &rows, int r0, int r1, int pad, int lo, int hi,
                std::vector<cv::Vec2i> &out) {
    out.clear();
    for (int r = std::max(0, r0); r < std::min(int(rows.size()), r1); ++r)
        for (const auto &run : rows[size_t(r)]) out.push_back({std::max(lo, run[0] - pad), std::min(hi, run[1] + pad)});
    std::sort(out.begin(), out.end(), [](const cv::Vec2i &a, const cv::Vec2i &b) { return a[0] < b[0]; });
    size_t n = 0;
    for (const auto &run : out) {
        if (run[0] >= run[1]) continue;
        if (n > 0 && run[0] <= out[n - 1][1]) out[n - 1][1] = std::max(out[n - 1][1], run[1]);
        else out[n++] = run;
    }
    out.resize(n);
}

} // namespace

// An AVX2 clone beside the baseline one (the same arithmetic, no FMA: the same corners).
__attribute__((target_clones("avx2", "default")))
std::vector<cv::Point2f> harris_corners(const cv::Mat &gray, const cv::Mat &mask, cv::Range rows,
                                        const LaneFeatureParams &p) {
    CV_Assert(gray.type() == CV_8UC1 && mask.type() == CV_8UC1 && mask.size() == gray.size());
    const int W = gray.cols;
    const int y0 = std::max(rows.start, 3), y1 = std::min(rows.end, gray.rows - 3);  // 3x3 window of 3x3 Sobel + NMS
    std::vector<cv::Point2f> out;
    if (y1 - y0 < 3) return out;
    // Streamed row by row through ring buffers of three rows, and only on the runs of region pixels:
    // gradient products one pixel around them (the 3x3 window), responses on them and one pixel
    // around (the 3x3 non-maximum suppression).
    std::vector<std::vector<cv::Vec2i>> mruns(size_t(y1 - y0 + 6));  // mask runs of rows y0-3 .. y1+2
    for (int r = 0; r < int(mruns.size()); ++r) row_runs(mask.ptr<uint8_t>(y0 - 3 + r), W, mruns[size_t(r)]);
    auto runs_of = [&](int y) -> const std::vector<cv::Vec2i> & { return mruns[size_t(y - y0 + 3)]; };
    // Per ring row: horizontal 3-sums of Ix^2, Iy^2, IxIy (separate arrays so the loops vectorise),
    // and the response.
    cv::Mat hxx(3, W, CV_32F), hyy(3, W, CV_32F), hxy(3, W, CV_32F), resp(3, W, CV_32F);
    std::vector<float> gxx(gray.cols), gyy(gray.cols), gxy(gray.cols);
    std::vector<cv::Vec2i> pruns, rruns;
    struct Cand { float r; int x, y; };
    std::vector<Cand> cand;
    float r_max = 0.f;
    __m128 r_max4 = _mm_setzero_ps();  // four lanes of r_max, folded in after the rows
    const float k = float(p.harris_k);
    for (int y = y0 - 2; y <= y1 + 1; ++y) {
        // Ix^2, Iy^2, IxIy of row y where the mask of rows y-2 .. y+2 reaches, then their 3-sums along the row
        union_runs(mruns, y - 2 - (y0 - 3), y + 3 - (y0 - 3), 2, 1, W - 1, pruns);
        {
            const uint8_t *a = gray.ptr<uint8_t>(y - 1), *b = gray.ptr<uint8_t>(y), *c = gray.ptr<uint8_t>(y + 1);
            float *sxx = hxx.ptr<float>((y + 3) % 3), *syy = hyy.ptr<float>((y + 3) % 3), *sxy = hxy.ptr<float>((y + 3) % 3);
            for (const auto &run : pruns) {
                for (int x = run[0]; x < run[1]; ++x) {
                    // 3x3 Sobel
                    const float ix = float((a[x + 1] - a[x - 1]) + 2 * (b[x + 1] - b[x - 1]) + (c[x + 1] - c[x - 1]));
                    const float iy = float((c[x - 1] - a[x - 1]) + 2 * (c[x] - a[x]) + (c[x + 1] - a[x + 1]));
                    gxx[size_t(x)] = ix * ix;
                    gyy[size_t(x)] = iy * iy;
                    gxy[size_t(x)] = ix * iy;
                }
                for (int x = run[0] + 1; x < run[1] - 1; ++x) {
                    sxx[x] = gxx[size_t(x - 1)] + gxx[size_t(x)] + gxx[size_t(x + 1)];
                    syy[x] = gyy[size_t(x - 1)] + gyy[size_t(x)] + gyy[size_t(x + 1)];
                    sxy[x] = gxy[size_t(x - 1)] + gxy[size_t(x)] + gxy[size_t(x + 1)];
                }
            }
        }
        // R = det M - k (trace M)^2 of row yr = y - 1, M the 3x3 sum of the products
        const int yr = y - 1;
        if (yr < y0 - 1) continue;
        union_runs(mruns, yr - 1 - (y0 - 3), yr + 2 - (y0 - 3), 1, 2, W - 2, rruns);
        {
            const int ra = (yr + 2) % 3, rb = (yr + 3) % 3, rc = (yr + 4) % 3;
            const float *xa = hxx.ptr<float>(ra), *xb = hxx.ptr<float>(rb), *xc = hxx.ptr<float>(rc);
            const float *ya = hyy.ptr<float>(ra), *yb = hyy.ptr<float>(rb), *yc = hyy.ptr<float>(rc);
            const float *ca = hxy.ptr<float>(ra), *cb = hxy.ptr<float>(rb), *cc = hxy.ptr<float>(rc);
            float *o = resp.ptr<float>(rb);
            for (const auto &run : rruns)
                for (int x = run[0]; x < run[1]; ++x) {
                    const float sx = xa[x] + xb[x] + xc[x], sy = ya[x] + yb[x] + yc[x], sc = ca[x] + cb[x] + cc[x];
                    const float tr = sx + sy;
                    o[x] = sx * sy - sc * sc - k * tr * tr;
                }
            // the largest response on region pixels (a row's runs are its region pixels), four at a time
            for (const auto &run : runs_of(yr)) {
                const int x1 = std::min(run[1], W - 2);
                int x = std::max(run[0], 2);
                for (; x + 4 <= x1; x += 4) r_max4 = _mm_max_ps(r_max4, _mm_loadu_ps(o + x));
                for (; x < x1; ++x) r_max = std::max(r_max, o[x]);
            }
        }
        // 3x3 local maxima of row yn = y - 2 (ties broken toward the first), on region pixels
        const int yn = y - 2;
        if (yn < y0 || yn >= y1) continue;
        const float *a = resp.ptr<float>((yn + 2) % 3), *b = resp.ptr<float>((yn + 3) % 3), *c = resp.ptr<float>((yn + 4) % 3);
        const __m128 zero = _mm_setzero_ps();
        for (const auto &run : runs_of(yn)) {
            const int x1 = std::min(run[1], W - 3);
            int x = std::max(run[0], 3);
            // The ten tests four pixels at a time, without branches (on a marking the response's sign and the
            // maxima are a coin toss to the branch predictor: the branchy loop took a third of the function).
            for (; x + 4 <= x1; x += 4) {
                const __m128 v = _mm_loadu_ps(b + x);
                __m128 ok = _mm_cmpgt_ps(v, zero);
                ok = _mm_and_ps(ok, _mm_cmpge_ps(v, _mm_loadu_ps(a + x - 1)));
                ok = _mm_and_ps(ok, _mm_cmpge_ps(v, _mm_loadu_ps(a + x)));
                ok = _mm_and_ps(ok, _mm_cmpge_ps(v, _mm_loadu_ps(a + x + 1)));
                ok = _mm_and_ps(ok, _mm_cmpge_ps(v, _mm_loadu_ps(b + x - 1)));
                ok = _mm_and_ps(ok, _mm_cmpgt_ps(v, _mm_loadu_ps(b + x + 1)));
                ok = _mm_and_ps(ok, _mm_cmpgt_ps(v, _mm_loadu_ps(c + x - 1)));
                ok = _mm_and_ps(ok, _mm_cmpgt_ps(v, _mm_loadu_ps(c + x)));
                ok = _mm_and_ps(ok, _mm_cmpgt_ps(v, _mm_loadu_ps(c + x + 1)));
                const int bits = _mm_movemask_ps(ok);
                if (!bits) continue;
                for (int i = 0; i < 4; ++i)
                    if (bits >> i & 1) cand.push_back({b[x + i], x + i, yn});
            }
            for (; x < x1; ++x) {
                const float v = b[x];
                if (v <= 0.f) continue;
                if (v < a[x - 1] || v < a[x] || v < a[x + 1] || v < b[x - 1] || v <= b[x + 1] || v <= c[x - 1] ||
                    v <= c[x] || v <= c[x + 1])
                    continue;
                cand.push_back({v, x, yn});
            }
        }
    }
    alignas(16) float lane_max[4];
    _mm_store_ps(lane_max, r_max4);
    r_max = std::max({r_max, lane_max[0], lane_max[1], lane_max[2], lane_max[3]});
    // Keep those above harris_quality of the strongest.
    const float thr = float(p.harris_quality) * r_max;
    cand.erase(std::remove_if(cand.begin(), cand.end(), [&](const Cand &c) { return c.r <= thr; }), cand.end());
    std::sort(cand.begin(), cand.end(), [](const Cand &a, const Cand &b) { return a.r > b.r; });
    // Strongest first, none within min distance of a kept one (grid of min-distance cells).
    const int d = std::max(1, p.min_corner_distance_px);
    const int gw = W / d + 1;
    std::vector<std::vector<cv::Point2f>> grid(size_t(gw) * size_t(gray.rows / d + 1));
    const float d2 = float(d * d);
    for (const auto &c : cand) {
        if (int(out.size()) >= p.max_corners) break;
        const int gx = c.x / d, gy = c.y / d;
        bool ok = true;
        for (int yy = std::max(0, gy - 1); yy <= gy + 1 && ok; ++yy)
            for (int xx = std::max(0, gx - 1); xx <= std::min(gw - 1, gx + 1) && ok; ++xx) {
                const size_t cell = size_t(yy) * size_t(gw) + size_t(xx);
                if (cell >= grid.size()) continue;
                for (const auto &q : grid[cell]) {
                    const float dx = q.x - float(c.x), dy = q.y - float(c.y);
                    if (dx * dx + dy * dy < d2) { ok = false; break; }
                }
            }
        if (!ok) continue;
        const cv::Point2f pt(float(c.x), float(c.y));
        grid[size_t(gy) * size_t(gw) + size_t(gx)].push_back(pt);
        out.push_back(pt);
    }
    return out;
}

namespace {

// Columns [i S, (i + 1) S) of the S x (S n) maps: the source coordinates M_i (u, v, 1) of patch i's pixel
// (u, v). All patches of a frame are then sampled by one cv::remap instead of one warpAffine each, whose
// per-call set-up (~10 us) was most of the patches' cost.
void affine_map(const cv::Matx23f &M, int S, int i, cv::Mat &mx, cv::Mat &my) {
    for (int v = 0; v < S; ++v) {
        float *x = mx.ptr<float>(v) + i * S, *y = my.ptr<float>(v) + i * S;
        const float x0 = M(0, 1) * float(v) + M(0, 2), y0 = M(1, 1) * float(v) + M(1, 2);
        for (int u = 0; u < S; ++u) {
            x[u] = x0 + M(0, 0) * float(u);
            y[u] = y0 + M(1, 0) * float(u);
        }
    }
}

} // namespace

std::vector<Correspondence> patch_lk(const cv::Mat &cur, const cv::Mat &prev, const std::vector<cv::Point2f> &corners,
                                     const cv::Matx33d &H_guess, bool predicted, const LaneFeatureParams &p) {
    CV_Assert(cur.type() == CV_8UC1 && prev.type() == CV_8UC1 && cur.size() == prev.size());
    std::vector<Correspondence> out;
    const int n = int(corners.size()), S = predicted ? p.lk_patch_px : p.lk_search_patch_px;
    const int levels = predicted ? p.lk_levels : p.lk_search_levels;
    if (n == 0) return out;
    const cv::Matx33d Hi = H_guess.inv();
    // Patches side by side: current ones in `cm`, pre-warped previous ones in `pm`.
    cv::Mat cm(S, S * n, CV_8UC1), pm, pmx(S, S * n, CV_32FC1), pmy(S, S * n, CV_32FC1);
    std::vector<cv::Point2f> g(corners.size());
    std::vector<cv::Matx22f> J(corners.size());
    const float c0 = 0.5f * float(S - 1);
    for (int i = 0; i < n; ++i) {
        const cv::Point2f c = corners[size_t(i)];
        // g = H^-1 c and the Jacobian of x -> H^-1 x at c: rows (h_r w - u_r h_3) / w^2.
        const cv::Vec3d q = Hi * cv::Vec3d(c.x, c.y, 1.0);
        const double w = q[2];
        g[size_t(i)] = cv::Point2f(float(q[0] / w), float(q[1] / w));
        cv::Matx22f Ji;
        for (int r = 0; r < 2; ++r)
            for (int k = 0; k < 2; ++k) Ji(r, k) = float((Hi(r, k) * w - q[r] * Hi(2, k)) / (w * w));
        J[size_t(i)] = Ji;
        cv::Mat cp = cm.colRange(i * S, (i + 1) * S);
        // Harris corners sit on whole pixels: then the current patch is a plain copy.
        const cv::Rect whole(int(c.x) - int(c0), int(c.y) - int(c0), S, S);
        if (c.x == std::floor(c.x) && c.y == std::floor(c.y) && c0 == std::floor(c0) &&
            (whole & cv::Rect(0, 0, cur.cols, cur.rows)) == whole)
            cur(whole).copyTo(cp);
        else
            cv::getRectSubPix(cur, cv::Size(S, S), c, cp);
        // pm(u) = prev(g + J (u - c0)), the previous frame pre-warped: the inverse map [J | g - J c0].
        affine_map(cv::Matx23f(Ji(0, 0), Ji(0, 1), g[size_t(i)].x - Ji(0, 0) * c0 - Ji(0, 1) * c0,
                               Ji(1, 0), Ji(1, 1), g[size_t(i)].y - Ji(1, 0) * c0 - Ji(1, 1) * c0),
                   S, i, pmx, pmy);
    }
    cv::remap(prev, pm, pmx, pmy, cv::INTER_LINEAR, cv::BORDER_REPLICATE);
    std::vector<cv::Point2f> start(corners.size()), fwd, back;
    for (int i = 0; i < n; ++i) start[size_t(i)] = cv::Point2f(float(i * S) + c0, c0);
    fwd = back = start;
    std::vector<uint8_t> st_f, st_b;
    std::vector<float> err;
    const cv::Size win(p.lk_window_px, p.lk_window_px);
    const cv::TermCriteria crit(cv::TermCriteria::COUNT | cv::TermCriteria::EPS, 10, 0.03);
    cv::calcOpticalFlowPyrLK(cm, pm, start, fwd, st_f, err, win, levels, crit, cv::OPTFLOW_USE_INITIAL_FLOW);
    cv::calcOpticalFlowPyrLK(pm, cm, fwd, back, st_b, err, win, levels, crit, cv::OPTFLOW_USE_INITIAL_FLOW);
    const float fb2 = float(p.fb_max_px * p.fb_max_px);
    const float reach = 0.5f * float(S - p.lk_window_px);  // farther the window left its patch
    for (int i = 0; i < n; ++i) {
        const cv::Point2f d = fwd[size_t(i)] - start[size_t(i)], e = back[size_t(i)] - start[size_t(i)];
        if (!st_f[size_t(i)] || !st_b[size_t(i)] || e.dot(e) > fb2 || std::fabs(d.x) > reach || std::fabs(d.y) > reach)
            continue;
        const cv::Matx22f &Ji = J[size_t(i)];
        const cv::Point2f pr(g[size_t(i)].x + Ji(0, 0) * d.x + Ji(0, 1) * d.y, g[size_t(i)].y + Ji(1, 0) * d.x + Ji(1, 1) * d.y);
        if (pr.x < 0 || pr.y < 0 || pr.x > float(prev.cols - 1) || pr.y > float(prev.rows - 1)) continue;
        out.push_back({pr, corners[size_t(i)]});
    }
    return out;
}

LaneFeatures lane_correspondences(const cv::Mat &cur, const cv::Mat &prev, cv::Point2f vp, const CameraParams &cam,
                                  const cv::Matx33d &H_guess, bool predicted, const LaneFeatureParams &p) {
    CV_Assert(cur.type() == CV_8UC1 && prev.type() == CV_8UC1 && cur.size() == prev.size());
    LaneFeatures out;
    const cv::Range rows = lane_feature_rows(cur.rows, vp.y, cam, p);
    if (rows.size() < 2) return out;
    cv::Mat binary;
    marking_response(cur, rows, vp.y, cam, p, binary);
    out.markings = marking_segments(binary, rows, vp, cam, p);
    if (out.markings.empty()) return out;
    cv::Mat mask = cv::Mat::zeros(cur.size(), CV_8UC1);
    for (const auto &m : out.markings) cv::fillConvexPoly(mask, m.region, cv::Scalar(255));
    out.corners = harris_corners(cur, mask, rows, p);
    out.matches = patch_lk(cur, prev, out.corners, H_guess, predicted, p);
    return out;
}

} // namespace hw
