#include "detect/parallax/aligned_difference.hpp"

#include "detect/photometric.hpp"
#include "cues/vehicle_top.hpp"
#include "geometry/homography_warp.hpp"

#include <opencv2/imgproc.hpp>

#include <algorithm>
#include <cmath>

namespace hw {

void ParallaxParams::bind(ParamMap &m) {
    m.add("level", level, 0, 3,
          "pyramid level of the aligned difference (0 full resolution, 1 half); 1 warps a quarter of the pixels and "
          "low-passes the sensor noise, while a vehicle's parallax at 60 m (~0.5 px at full resolution) still shows");
    m.add("cell_w_px", cell_w_px, 1, 256, "px at full resolution; width of a SAD cell");
    m.add("cell_h_px", cell_h_px, 1, 256,
          "px at full resolution; height of a SAD cell; small, because the difference at a vehicle's bottom edge is "
          "a band a few pixels tall");
    m.add("sad_min", sad_min, 0.0, 255.0,
          "gray levels; a cell is hot only if its mean |difference| exceeds this, whatever the road's own residual");
    m.add("sad_factor", sad_factor, 1.0, 100.0,
          "a cell is hot above this many times the median |difference| of the road cells (the alignment residual "
          "of this frame: texture, noise, shake the homography missed)");
    m.add("edge_slack_px", edge_slack_px, 0.0, 10.0,
          "px at the difference's level; a cell is hot only if its mean |difference| exceeds this times its "
          "mean gradient (more than interpolation blur at edges); 0 disables");
    m.add("photometric", photometric,
          "take the smooth brightness change between the aligned frames out of the difference (a quadratic "
          "surface; vignetting, a low sun's sheen; docs/tracking.md)");
    m.add("photometric_trim", photometric_trim, 1.0, 100.0,
          "robust sigmas (1.4826 MAD) beyond which a road cell is left out of the brightness fit (vehicles, moving "
          "shadows)");
    m.add("min_width_frac", min_width_frac, 0.01, 1.0,
          "expected widths; a narrower region is no vehicle; 0.3 still takes a vehicle a third inside the image "
          "(entering from the side)");
    m.add("inside_margin_m", inside_margin_m, -10.0, 10.0,
          "m; most hot cells of a region's bottom band must lie this far inside the road area of the lane model: a "
          "vehicle's contact zone is mostly inside its lane, a streak along the road edge or a guardrail sits on the "
          "border");
    m.add("max_width_frac", max_width_frac, 1.0, 10.0,
          "expected widths; a wider region is no single vehicle (a shadow band, an overpass edge)");
    m.add("bottom_band_frac", bottom_band_frac, 0.0, 2.0,
          "expected widths; a region's width is measured over its lowest rows this tall (the contact zone spans the "
          "vehicle; a guardrail or marking streak joined to it rises sideways)");
    m.add("side_frac", side_frac, 0.0, 1.0,
          "a region's sides are the outermost columns of its bottom band whose mean |difference| reaches this share "
          "of the band's strong columns (90th percentile)");
    m.add("body_min_frac", body_min_frac, 0.0, 1.0,
          "the sides are taken from the region's body (above its bottom band) when the body's difference spans at "
          "least this share of the band's width; the band is widened by what moves beside the vehicle on the road "
          "(its cast shadow)");
    m.add("height_hot_frac", height_hot_frac, 0.0, 1.0,
          "share of a region's columns that must be hot for a row to count towards its height");
    m.add("height_gap_frac", height_gap_frac, 0.0, 2.0,
          "widths; rows without difference bridged while measuring the height (the flat back of a truck)");
    m.add("min_aspect", min_aspect, 0.1, 5.0,
          "box height / width reported at least (a region whose upper edges showed no parallax); at most: "
          "vehicle_shape.max_aspect");
    m.add("find_top", find_top,
          "take a region's top from the current frame's side edges under a roof line when that is higher than "
          "vehicle_shape.top_min_aspect widths, up to vehicle_shape.max_height_m above the road at its bottom row (a "
          "truck's flat back shows no parallax; a cut vehicle's visible width says nothing of its height; "
          "docs/tracking.md)");
    m.add("top_keep_frac", top_keep_frac, 0.05, 1.0,
          "share of the side edges' strength on the lower body that still counts as a side going up (as the thesis "
          "preset's top_keep_frac)");
    m.add("top_max_gap", top_max_gap, 0, 50, "px; gaps in the side edges bridged going up (seams, a window frame)");
    m.add("top_snap_frac", top_snap_frac, 0.0, 1.0,
          "region widths; each side is first moved to the strongest vertical edge within this distance on the "
          "lower body before the top is searched");
    m.add("join_gap_cells", join_gap_cells, 0, 100,
          "cells; hot clusters this far beside a region's columns still join it (the difference of one vehicle is "
          "broken at its wheels and plate)");
    m.add("streak_elongation", streak_elongation, 1.0, 1000.0,
          "a region whose road cells are this elongated (sqrt of the eigenvalue ratio of their scatter) ... (5: "
          "guardrail streaks are longer; a vehicle's smear along the road from its own motion is shorter)");
    m.add("streak_angle_deg", streak_angle_deg, 0.0, 90.0,
          "... and whose long axis points within this angle at the vanishing point is a structure along the road "
          "(guardrail, kerb, an edge line's residual), not a vehicle");
    m.add("refine_up_frac", refine_up_frac, 0.0, 2.0,
          "expected widths above the lowest hot row searched for the shadow step that is the vehicle's bottom");
    m.add("refine_down_frac", refine_down_frac, 0.0, 2.0,
          "expected widths; how far below a region the search for its vehicle's bottom edge goes (a vehicle "
          "standing still shows no parallax at its contact zone; docs/tracking.md)");
    m.add("refine_min_step", refine_min_step, 0.0, 255.0,
          "gray levels; weakest dark-above / bright-below step taken as the bottom; otherwise the hot row stays");
    m.add("bottom_margin_px", bottom_margin_px, 0.0, 1000.0,
          "px; a region reaching this close to the bottom of the road area (image bottom or bonnet) is cut by it: "
          "the near road's residual, not a vehicle (whose contact zone is in view from 3-4 m on)");
    m.add("horizon_margin_px", horizon_margin_px, 0.0, 1000.0,
          "px; a region's bottom must be this far below the horizon (structures above the road start higher)");
}

namespace {

struct Component {
    int label;
    int x0, x1, y0, y1;  // cells, inclusive
    float sad_sum;
    int cells;
};

struct Region {
    int x0, x1, y0, y1;  // cells, inclusive (y1 = bottom)
    float sad_sum;
    int cells;
    std::vector<int> labels;  // its clusters
};

// Columns where row y crosses a polygon: [xl, xr] between its leftmost and rightmost crossing
// (false for no polygon or a row outside it; a point exactly on a vertex counts).
bool polygon_span(const std::vector<cv::Point> &poly, float y, float &xl, float &xr) {
    if (poly.size() < 3) return false;
    xl = 1e9f;
    xr = -1e9f;
    for (size_t i = 0; i < poly.size(); ++i) {
        const cv::Point2f a = poly[i], b = poly[(i + 1) % poly.size()];
        if ((y < std::min(a.y, b.y)) || (y > std::max(a.y, b.y))) continue;
        const float x = a.y == b.y ? a.x : a.x + (b.x - a.x) * (y - a.y) / (b.y - a.y);
        xl = std::min(xl, a.y == b.y ? std::min(a.x, b.x) : x);
        xr = std::max(xr, a.y == b.y ? std::max(a.x, b.x) : x);
    }
    return xl <= xr;
}

// Narrows the columns [a, b) of `diff` to the outermost ones whose mean |difference| over rows
// [r0, r1) reaches `frac` of the strong columns (the 90th percentile).
void side_extent(const cv::Mat &diff, int r0, int r1, float frac, int &a, int &b) {
    r0 = std::max(r0, 0);
    r1 = std::min(r1, diff.rows);
    a = std::max(a, 0);
    b = std::min(b, diff.cols);
    if (r1 <= r0 || b <= a) return;
    cv::Mat prof;
    cv::reduce(diff(cv::Range(r0, r1), cv::Range(a, b)), prof, 0, cv::REDUCE_AVG, CV_32F);
    std::vector<float> v(prof.begin<float>(), prof.end<float>()), sorted = v;
    std::sort(sorted.begin(), sorted.end());
    const float lim = frac * sorted[size_t(0.9 * double(sorted.size() - 1))];
    int i = 0, j = int(v.size()) - 1;
    while (i < j && v[size_t(i)] < lim) ++i;
    while (j > i && v[size_t(j)] < lim) --j;
    b = a + j + 1;
    a = a + i;
}

// Strongest dark-above / bright-below step (mean over columns c0..c1 of I(y+1) - I(y-1)) in rows y0..y1.
bool bottom_step(const cv::Mat &gray, int c0, int c1, int y0, int y1, float min_step, float &row) {
    c0 = std::max(c0, 0);
    c1 = std::min(c1, gray.cols - 1);
    y0 = std::max(y0, 1);
    y1 = std::min(y1, gray.rows - 2);
    if (c1 < c0 || y1 < y0) return false;
    float best = min_step;
    bool found = false;
    for (int y = y0; y <= y1; ++y) {
        const uint8_t *a = gray.ptr<uint8_t>(y - 1), *b = gray.ptr<uint8_t>(y + 1);
        int s = 0;
        for (int x = c0; x <= c1; ++x) s += int(b[x]) - int(a[x]);
        const float step = float(s) / float(c1 - c0 + 1);
        if (step > best) {
            best = step;
            row = float(y);
            found = true;
        }
    }
    return found;
}

} // namespace

ParallaxFrame detect_parallax(const cv::Mat &cur_band, const cv::Mat &prev_band, const cv::Mat &cur_full, int band_top,
                              const cv::Matx33d &H, const LaneModel &lanes, cv::Point2f vp, const CameraParams &cam,
                              const ParallaxParams &p, cv::Mat *grad_cells) {
    const float horizon_row = vp.y, vp_x = vp.x;
    CV_Assert(cur_band.type() == CV_8UC1 && prev_band.type() == CV_8UC1 && cur_band.size() == prev_band.size());
    CV_Assert(cur_full.type() == CV_8UC1 && band_top >= 0 && band_top < cur_full.rows);
    ParallaxFrame out;
    const int sc = 1 << p.level;
    const double f = 1.0 / sc;
    // Band coordinates at this level: u = f x, v = f (y - band_top); H_s = S H S^-1.
    const cv::Matx33d S(f, 0, 0, 0, f, -f * band_top, 0, 0, 1);
    const cv::Matx33d Hs = S * H * S.inv();
    cv::Mat warped, diff;
    warp_homography(prev_band, Hs, cur_band.size(), warped);

    const int cw = std::max(1, p.cell_w_px / sc), ch = std::max(1, p.cell_h_px / sc);
    const int ncx = cur_band.cols / cw, ncy = cur_band.rows / ch;
    if (ncx < 1 || ncy < 1) return out;
    // Road cells: inside the lane model's road area (below the horizon when there is none).
    const float cell_px_w = float(cw * sc), cell_px_h = float(ch * sc);  // cell size in full-resolution px
    auto cell_x = [&](float c) { return c * cell_px_w; };                   // full-res x of a cell edge
    auto cell_y = [&](float r) { return float(band_top) + r * cell_px_h; }; // full-res y of a cell edge
    cv::Mat road = cv::Mat::zeros(ncy, ncx, CV_8UC1);
    float road_bottom = float(cur_full.rows - 1);
    if (lanes.road_polygon.size() >= 3) {
        road_bottom = 0.f;
        for (const auto &q : lanes.road_polygon) road_bottom = std::max(road_bottom, float(q.y));
        std::vector<cv::Point> poly;
        for (const auto &q : lanes.road_polygon)
            poly.emplace_back(cvRound(q.x / cell_px_w - 0.5f), cvRound((q.y - band_top) / cell_px_h - 0.5f));
        cv::fillPoly(road, std::vector<std::vector<cv::Point>>{poly}, cv::Scalar(255));
    } else {
        const int r0 = std::clamp(int(std::ceil((horizon_row - band_top) / cell_px_h)), 0, ncy);
        road.rowRange(r0, ncy).setTo(255);
    }

    // The absolute difference, after the smooth brightness change between the aligned frames is taken
    // out (photometric.hpp: a road point seen elsewhere in the image is seen brighter or darker).
    if (p.photometric) {
        // Fitted on the mean signed difference of blocks of 4 x 4 cells (box means of the int16 difference):
        // a quadratic surface needs a few hundred of them, not thousands.
        cv::Mat d, df, means, use;
        cv::subtract(cur_band, warped, d, cv::noArray(), CV_16S);
        const int B = 4, bx = ncx / B, by = ncy / B;
        if (bx >= 4 && by >= 3) {
            d(cv::Rect(0, 0, bx * B * cw, by * B * ch)).convertTo(df, CV_32F);
            cv::resize(df, means, cv::Size(bx, by), 0, 0, cv::INTER_AREA);
            cv::resize(road(cv::Rect(0, 0, B * bx, B * by)), use, cv::Size(bx, by), 0, 0, cv::INTER_NEAREST);
            out.brightness = fit_brightness_cells(means, use, double(B * cw), double(B * ch), cur_band.size(), p.photometric_trim);
        }
        compensated_absdiff(d, out.brightness, diff);
    } else {
        cv::absdiff(cur_band, warped, diff);
    }

    // SAD per cell.
    // Per cell: the mean |difference| (SAD / pixels) and the mean gradient magnitude of the current
    // band, (|I(x+1) - I(x-1)| + |I(y+1) - I(y-1)|) / 4 (central differences, L1, halved).
    // Row sums first (plain loops over whole rows, which vectorise), then per cell. The gradient cells
    // depend on the current band only: a second call on the same band takes them from `grad_cells`.
    const bool have_grad = grad_cells && grad_cells->type() == CV_32F && grad_cells->size() == cv::Size(ncx, ncy);
    cv::Mat sad = cv::Mat::zeros(ncy, ncx, CV_32F), grad = have_grad ? *grad_cells : cv::Mat::zeros(ncy, ncx, CV_32F);
    const int W = ncx * cw;
    std::vector<int> g_row(size_t(W) + 1);
    for (int y = 0; y < ncy * ch; ++y) {
        const uint8_t *d = diff.ptr<uint8_t>(y);
        float *s = sad.ptr<float>(y / ch);
        for (int cc = 0; cc < ncx; ++cc) {
            int sd = 0;
            for (int x = cc * cw; x < (cc + 1) * cw; ++x) sd += d[x];
            s[cc] += float(sd);
        }
        if (have_grad) continue;
        const uint8_t *c = cur_band.ptr<uint8_t>(y);
        const uint8_t *up = cur_band.ptr<uint8_t>(std::max(y - 1, 0)), *dn = cur_band.ptr<uint8_t>(std::min(y + 1, diff.rows - 1));
        int *g = g_row.data();
        g[0] = std::abs(int(c[1]) - int(c[0])) + std::abs(int(dn[0]) - int(up[0]));
        for (int x = 1; x < W; ++x) {
            const int xr = x + 1 < diff.cols ? x + 1 : x;
            g[x] = std::abs(int(c[xr]) - int(c[x - 1])) + std::abs(int(dn[x]) - int(up[x]));
        }
        float *gr = grad.ptr<float>(y / ch);
        for (int cc = 0; cc < ncx; ++cc) {
            int sg = 0;
            for (int x = cc * cw; x < (cc + 1) * cw; ++x) sg += g[x];
            gr[cc] += float(sg);
        }
    }
    sad *= 1.0 / double(cw * ch);
    if (!have_grad) {
        grad *= 0.25 / double(cw * ch);
        if (grad_cells) *grad_cells = grad;
    }

    // Threshold from the road cells' own residual.
    std::vector<float> road_sad;
    for (int r = 0; r < ncy; ++r)
        for (int c = 0; c < ncx; ++c)
            if (road.at<uint8_t>(r, c)) road_sad.push_back(sad.at<float>(r, c));
    if (road_sad.empty()) return out;
    std::nth_element(road_sad.begin(), road_sad.begin() + road_sad.size() / 2, road_sad.end());
    const float thr = std::max(float(p.sad_min), float(p.sad_factor) * road_sad[road_sad.size() / 2]);
    out.threshold = thr;
    // Hot: above the threshold, and more than edge_slack_px of displacement of the local gradient
    // (a high-contrast marking edge differs by a few gray levels after any warp: interpolation blur
    // and the last tenths of a pixel of alignment error), and inside what the warp could fill from
    // the previous band (its border rows are replicated, not seen).
    cv::Mat hot = (sad > thr) & (sad > float(p.edge_slack_px) * grad);
    {
        const cv::Matx33d Hi = Hs.inv();
        for (int r = 0; r < ncy; ++r)
            for (int c = 0; c < ncx; ++c) {
                const cv::Vec3d q = Hi * cv::Vec3d((c + 0.5) * cw, (r + 0.5) * ch, 1.0);
                const double u = q[0] / q[2], v = q[1] / q[2];
                if (!(q[2] > 0) || u < 0 || v < 0 || u > prev_band.cols - 1 || v > prev_band.rows - 1) hot.at<uint8_t>(r, c) = 0;
            }
    }
    out.hot_cells = cv::countNonZero(hot);
    out.hot = hot;
    out.cell = cv::Size2f(cell_px_w, cell_px_h);
    {
        double sum = 0;
        int n = 0;
        for (int r = 0; r < ncy; ++r)
            for (int c = 0; c < ncx; ++c)
                if (road.at<uint8_t>(r, c) && !hot.at<uint8_t>(r, c)) { sum += sad.at<float>(r, c); ++n; }
        out.road_residual = n ? float(sum / n) : kNaN;
    }

    // Clusters of hot cells, scanned bottom-up.
    // Clusters are formed on the road area only, so that what stands beside the road (guardrails,
    // trees, posts) neither starts a region nor joins vehicles to each other through it.
    cv::Mat hot_road = hot & road;
    cv::Mat labels, stats, centroids;
    const int nl = cv::connectedComponentsWithStats(hot_road, labels, stats, centroids, 8, CV_32S);
    std::vector<Component> comps;
    for (int l = 1; l < nl; ++l) {
        const int x0 = stats.at<int>(l, cv::CC_STAT_LEFT), y0 = stats.at<int>(l, cv::CC_STAT_TOP);
        Component c{l, x0, x0 + stats.at<int>(l, cv::CC_STAT_WIDTH) - 1, y0, y0 + stats.at<int>(l, cv::CC_STAT_HEIGHT) - 1,
                    0.f, 0};
        for (int r = c.y0; r <= c.y1; ++r)
            for (int x = c.x0; x <= c.x1; ++x)
                if (labels.at<int>(r, x) == l) {
                    c.sad_sum += sad.at<float>(r, x);
                    ++c.cells;
                }
        comps.push_back(c);
    }
    std::sort(comps.begin(), comps.end(), [](const Component &a, const Component &b) {
        return a.y1 != b.y1 ? a.y1 > b.y1 : a.x0 < b.x0;
    });
    // A cluster joins a region when it lies within the region's columns (+- join_gap_cells) and no
    // higher above its bottom than vehicle_shape.max_aspect region widths (a vehicle is not wider above its bottom,
    // nor taller than that); a cluster at the region's bottom rows beside it widens it (one vehicle's
    // difference broken at the wheels). Any other cluster starts a region.
    std::vector<Region> regions;
    const float rows_per_col = cell_px_w / cell_px_h;
    for (const auto &c : comps) {
        Region *home = nullptr;
        for (auto &g : regions) {
            const float tall = float(p.shape.max_aspect) * float(g.x1 - g.x0 + 1) * rows_per_col;
            const bool beside = c.y1 >= g.y1 - 1 && c.x1 >= g.x0 - p.join_gap_cells && c.x0 <= g.x1 + p.join_gap_cells;
            const bool above = c.x0 >= g.x0 - p.join_gap_cells && c.x1 <= g.x1 + p.join_gap_cells && c.y0 >= g.y1 - tall;
            if (beside || above) {
                home = &g;
                if (beside) {
                    home->x0 = std::min(home->x0, c.x0);
                    home->x1 = std::max(home->x1, c.x1);
                }
                break;
            }
        }
        if (home) {
            home->labels.push_back(c.label);
            home->y0 = std::min(home->y0, c.y0);
            home->sad_sum += c.sad_sum;
            home->cells += c.cells;
        } else {
            regions.push_back({c.x0, c.x1, c.y0, c.y1, c.sad_sum, c.cells, {c.label}});
        }
    }

    for (const auto &g : regions) {
        float yb = cell_y(float(g.y1 + 1));
        const float w_exp = float(std::max(0.0, p.shape.width_m * cam.fx * (yb - horizon_row) / (cam.fy * cam.height_m)));
        // The width is that of the region's bottom band (bottom_band_frac expected widths tall): the
        // contact zone spans the vehicle, while a guardrail or marking streak joined to it rises sideways.
        const int band_rows = std::max(1, int(std::lround(float(p.bottom_band_frac) * w_exp / cell_px_h)));
        // Its cells there must mostly lie inside the road area by inside_margin_m (a vehicle's contact
        // zone is at least half a vehicle inside its lane; a streak along the road's edge is on it).
        int bx0 = g.x1, bx1 = g.x0, n_band = 0, n_inside = 0;
        for (int r = std::max(g.y0, g.y1 - band_rows + 1); r <= g.y1; ++r) {
            const float yr = cell_y(r + 0.5f);
            float xl = -1e9f, xr = 1e9f;
            const bool span = polygon_span(lanes.road_polygon, yr, xl, xr);
            const float margin = float(p.inside_margin_m * cam.fx * (yr - horizon_row) / (cam.fy * cam.height_m));
            for (int x = g.x0; x <= g.x1; ++x)
                if (hot.at<uint8_t>(r, x) && std::find(g.labels.begin(), g.labels.end(), labels.at<int>(r, x)) != g.labels.end()) {
                    bx0 = std::min(bx0, x);
                    bx1 = std::max(bx1, x);
                    ++n_band;
                    const float xc = cell_x(x + 0.5f);
                    if (!span || (xc - xl >= margin && xr - xc >= margin)) ++n_inside;
                }
        }
        if (bx1 < bx0 || 2 * n_inside < n_band) continue;
        // Shape of the region's road cells: a structure along the road (guardrail, kerb, the edge line's
        // residual) leaves a thin streak pointing at the vanishing point; a vehicle a compact blob, or
        // bands across its rear (bumper, contact zone) that run across the road, not along it.
        float elong = 1.f, along = 0.f;
        {
            double n = 0, sx = 0, sy = 0, sxx = 0, syy = 0, sxy = 0;
            for (int r = g.y0; r <= g.y1; ++r)
                for (int x = g.x0; x <= g.x1; ++x)
                    if (hot_road.at<uint8_t>(r, x) &&
                        std::find(g.labels.begin(), g.labels.end(), labels.at<int>(r, x)) != g.labels.end()) {
                        const double u = cell_x(x + 0.5f), v = cell_y(r + 0.5f);
                        n += 1; sx += u; sy += v; sxx += u * u; syy += v * v; sxy += u * v;
                    }
            if (n > 2) {
                const double mx = sx / n, my = sy / n;
                const double cxx = sxx / n - mx * mx, cyy = syy / n - my * my, cxy = sxy / n - mx * my;
                const double tr = cxx + cyy, det = cxx * cyy - cxy * cxy;
                const double disc = std::sqrt(std::max(0.0, tr * tr / 4 - det));
                const double l1 = tr / 2 + disc, l2 = std::max(1e-6, tr / 2 - disc);
                elong = float(std::sqrt(l1 / l2));
                // major axis (eigenvector of l1) against the direction to the vanishing point
                double ax = cxy, ay = l1 - cxx;
                if (std::fabs(ax) + std::fabs(ay) < 1e-9) { ax = 1; ay = 0; }
                const double vx = vp_x - mx, vy = horizon_row - my;
                along = float(std::fabs(ax * vx + ay * vy) / (std::hypot(ax, ay) * std::hypot(vx, vy) + 1e-9));
            }
        }
        if (elong >= float(p.streak_elongation) && along >= float(std::cos(p.streak_angle_deg * M_PI / 180.0))) continue;
        // Sides to a pixel of the level from the bottom band first (trims cell quantisation).
        const int band_r0 = std::max(g.y0, g.y1 - band_rows + 1) * ch, band_r1 = (g.y1 + 1) * ch;
        int la = bx0 * cw, lb = (bx1 + 1) * cw;  // level columns [la, lb)
        side_extent(diff, band_r0, band_r1, float(p.side_frac), la, lb);
        float x0 = float(la * sc), x1 = float(lb * sc);
        float w = x1 - x0;
        // Below the horizon, and not cut by the bottom of the road band: a vehicle whose contact zone is
        // out of view would be nearer than the camera sees the road (3-4 m); what is cut there is the near
        // road's own residual.
        if (yb < horizon_row + float(p.horizon_margin_px) || w_exp <= 0.f) continue;
        if (g.y1 >= ncy - 1 || cell_y(float(g.y1 + 1)) >= road_bottom - float(p.bottom_margin_px)) continue;
        if (w < float(p.min_width_frac) * w_exp || w > float(p.max_width_frac) * w_exp) continue;
        ParallaxMeasurement m;
        float row = yb;
        // The step is searched on the road only: below road_bottom lies the bonnet, whose edge is a strong
        // dark-above / bright-below step of its own.
        const int refine_y1 = int(std::min(yb + float(p.refine_down_frac) * w_exp, road_bottom - float(p.bottom_margin_px)));
        if (bottom_step(cur_full, int(x0 + 0.2f * w), int(x1 - 0.2f * w), int(yb - float(p.refine_up_frac) * w_exp),
                        refine_y1, float(p.refine_min_step), row)) {
            yb = row;
            m.refined = true;
        }
        // Height: up from the bottom through rows where height_hot_frac of the region's columns are hot
        // (anywhere: the vehicle's top may stand above the road area), bridging gaps of up to
        // height_gap_frac widths (the flat back of a truck shows no difference).
        int top = g.y1, gap = 0;
        const int max_rows = int(float(p.shape.max_aspect) * w / cell_px_h);
        const int max_gap = std::max(p.join_gap_cells, int(float(p.height_gap_frac) * w / cell_px_h));
        for (int r = g.y1; r >= std::max(0, g.y1 - max_rows) && gap <= max_gap; --r) {
            const int n_hot = cv::countNonZero(hot.row(r).colRange(bx0, bx1 + 1));
            if (float(n_hot) >= float(p.height_hot_frac) * float(bx1 - bx0 + 1)) { top = r; gap = 0; } else ++gap;
        }
        // The body above the bottom band gives the sides when it differs enough: the band is widened by
        // what moves with the vehicle on the road beside it (its cast shadow, the smear of its contact zone).
        if (top * ch < band_r0 - 1) {
            int ba = la, bb = lb;
            side_extent(diff, top * ch, band_r0, float(p.side_frac), ba, bb);
            if (bb - ba >= int(float(p.body_min_frac) * float(lb - la))) {
                x0 = float(ba * sc);
                x1 = float(bb * sc);
                w = x1 - x0;
            }
        }
        float h = std::clamp(yb - cell_y(float(top)), float(p.min_aspect) * w, float(p.shape.max_aspect) * w);
        // The top from the current frame where the difference cannot give it: the flat back of a truck shows
        // no parallax, and the road band ends band_above_horizon above the horizon, below the roof of any
        // near van or truck. The vehicle's sides are vertical edges up to its roof (vehicle_top.hpp); a side
        // within a cell of the image's side is cut by it (an overtaking vehicle) and only the inner one is
        // followed, the search bounded by a height in metres (the visible width of a cut vehicle says
        // nothing about its height).
        if (p.find_top) {
            const bool cut_l = x0 <= cell_px_w, cut_r = x1 >= float(cur_full.cols - 1) - cell_px_w;
            if (!(cut_l && cut_r)) {
                const auto [r0, r1] = lower_body_rows(yb, w);
                const float rad = float(p.top_snap_frac) * w;
                const float l = cut_l ? x0 : snap_side(cur_full, x0, r0, r1, rad);
                const float r = cut_r ? x1 : snap_side(cur_full, x1, r0, r1, rad);
                const float px_per_m = (yb - horizon_row) / float(cam.height_m);  // flat road, at the bottom row
                const float t = vehicle_top_between(cur_full, l, r, yb, r - l,
                                                    int(std::floor(yb - float(p.shape.max_height_m) * px_per_m)),
                                                    yb - float(p.shape.top_min_aspect) * (r - l), !cut_l, !cut_r,
                                                    p.top_keep_frac, p.top_max_gap);
                if (std::isfinite(t)) h = yb - t;
            }
        }
        m.point = {0.5f * (x0 + x1), yb};
        m.box = cv::Rect2f(x0, yb - h, w, h);
        m.sad = g.cells ? g.sad_sum / float(g.cells) : 0.f;
        out.measurements.push_back(m);
    }
    return out;
}

} // namespace hw
