#include "geometry/homography_refine.hpp"

#include <opencv2/imgproc.hpp>

#include <algorithm>
#include <cmath>

namespace hw {

void HomographyRefineParams::bind(ParamMap &m) {
    m.add("refine_iterations", iterations, 0, 10,
          "Gauss-Newton steps refining the filtered homography on the road pixels (a vertical shift and an extra "
          "travel, homography_refine.hpp), aimed at the far road where the marking fit is 1-1.5 px off (TME tme08); "
          "measured: one step takes the TME residual from 2.56 to 2.49 gray levels, costs ~0.55 ms per 640x480 frame "
          "and did not make the vehicles there trackable, so 0 (off) by default");
    m.add("refine_outlier_gray", outlier_gray, 1.0, 255.0,
          "gray levels; road pixels whose aligned difference exceeds this are left out of the refinement (vehicles, "
          "structures above the road)");
    m.add("refine_max_shift_px", max_shift_px, 0.0, 100.0,
          "px; a refinement step asking for a larger vertical shift is refused (the refinement only polishes)");
    m.add("refine_max_travel_m", max_travel_m, 0.0, 10.0,
          "m; a refinement step asking for a larger extra travel is refused");
}

HomographyRefinement refine_road_homography(const cv::Mat &cur_band, const cv::Mat &prev_band, int band_top, int level,
                                            const cv::Matx33d &H, const std::vector<cv::Point> &road, cv::Point2f vp,
                                            const CameraParams &cam, const HomographyRefineParams &p) {
    CV_Assert(cur_band.type() == CV_8UC1 && prev_band.type() == CV_8UC1 && cur_band.size() == prev_band.size());
    HomographyRefinement out;
    out.H = H;
    if (p.iterations <= 0 || !std::isfinite(vp.x) || !std::isfinite(vp.y)) return out;
    const int sc = 1 << level;
    const double f = 1.0 / sc;
    const cv::Matx33d S(f, 0, 0, 0, f, -f * band_top, 0, 0, 1), Si = S.inv();
    // Road pixels of the band at this level.
    cv::Mat mask = cv::Mat::zeros(cur_band.size(), CV_8UC1);
    if (road.size() >= 3) {
        std::vector<cv::Point> poly;
        for (const auto &q : road) poly.emplace_back(cvRound(f * q.x), cvRound(f * (q.y - band_top)));
        cv::fillPoly(mask, std::vector<std::vector<cv::Point>>{poly}, cv::Scalar(255));
    } else {
        mask.rowRange(std::clamp(int(std::ceil(f * (vp.y - band_top))) + 1, 0, mask.rows), mask.rows).setTo(255);
    }
    const double k = 1.0 / (cam.fy * cam.height_m);  // travel flow per m: (y - y_h)^2 k
    const double vs = 0.5 * cur_band.rows;             // row scale of the brightness terms
    cv::Matx33d Hc = H;
    cv::Mat warped;
    for (int it = 0; it < p.iterations; ++it) {
        cv::warpPerspective(prev_band, warped, S * Hc * Si, cur_band.size(), cv::INTER_LINEAR, cv::BORDER_REPLICATE);
        // Normal equations of [g.flow_d, g.flow_s, 1, v, v^2] (parameters d px, s m, b0..b2), over the
        // road pixels one pixel inside the band (central differences); upper triangle only, in float per
        // row, summed in double (the brightness columns are constant along a row).
        double A[5][5] = {}, b[5] = {};
        long n = 0;
        for (int v = 1; v < cur_band.rows - 1; ++v) {
            const uint8_t *m = mask.ptr<uint8_t>(v), *c = cur_band.ptr<uint8_t>(v), *w = warped.ptr<uint8_t>(v);
            const uint8_t *cu = cur_band.ptr<uint8_t>(v - 1), *cd = cur_band.ptr<uint8_t>(v + 1);
            const uint8_t *wu = warped.ptr<uint8_t>(v - 1), *wd = warped.ptr<uint8_t>(v + 1);
            const double y = band_top + sc * v, dyh = y - vp.y;
            if (dyh <= 1.0) continue;
            const float vv = float(v / vs - 1.0);
            const float kx = float(k * dyh * sc), ky = float(k * dyh * dyh), vx = float(vp.x) / float(sc), g = 0.25f / float(sc);
            float a00 = 0, a01 = 0, a02 = 0, a11 = 0, a12 = 0, a22 = 0, b0 = 0, b1 = 0, b2 = 0;
            for (int u = 1; u < cur_band.cols - 1; ++u) {
                if (!m[u]) continue;
                const float r = float(c[u]) - float(w[u]);
                if (std::fabs(r) > float(p.outlier_gray)) continue;
                // gradient per full-resolution px, averaged over both images
                const float gx = g * (float(c[u + 1]) - c[u - 1] + float(w[u + 1]) - w[u - 1]);
                const float gy = g * (float(cd[u]) - cu[u] + float(wd[u]) - wu[u]);
                // r ~ -(grad . flow) + brightness: the flow columns carry the minus sign
                const float j0 = -gy, j1 = -(gx * (float(u) - vx) * kx + gy * ky);
                a00 += j0 * j0; a01 += j0 * j1; a11 += j1 * j1;
                a02 += j0; a12 += j1; a22 += 1.f;
                b0 += j0 * r; b1 += j1 * r; b2 += r;
            }
            const double rv[3] = {1.0, vv, double(vv) * vv};
            A[0][0] += a00; A[0][1] += a01; A[1][1] += a11;
            for (int q = 0; q < 3; ++q) {
                A[0][2 + q] += a02 * rv[q];
                A[1][2 + q] += a12 * rv[q];
                for (int t = q; t < 3; ++t) A[2 + q][2 + t] += a22 * rv[q] * rv[t];
                b[2 + q] += b2 * rv[q];
            }
            b[0] += b0;
            b[1] += b1;
            n += long(a22);
        }
        cv::Matx<double, 5, 5> AA;
        cv::Vec<double, 5> bb;
        for (int r = 0; r < 5; ++r) {
            bb[r] = b[r];
            for (int c = 0; c < 5; ++c) AA(r, c) = c >= r ? A[r][c] : A[c][r];
        }
        if (n < 200) return out;
        cv::Vec<double, 5> q;
        if (!cv::solve(AA, bb, q, cv::DECOMP_CHOLESKY)) return out;
        const double d = q[0], s = q[1];
        if (!std::isfinite(d) || !std::isfinite(s) || std::fabs(d) > p.max_shift_px || std::fabs(s) > p.max_travel_m)
            return out;
        // F(s): the exact travel about the vanishing point, T_v diag-ish T_v^-1 (see the header).
        const cv::Matx33d Tv(1, 0, vp.x, 0, 1, vp.y, 0, 0, 1), Tvi(1, 0, -vp.x, 0, 1, -vp.y, 0, 0, 1);
        const cv::Matx33d F = Tv * cv::Matx33d(1, 0, 0, 0, 1, 0, 0, -s * k, 1) * Tvi;
        const cv::Matx33d D(1, 0, 0, 0, 1, d, 0, 0, 1);
        Hc = F * D * Hc;
        Hc = Hc * (1.0 / Hc(2, 2));
        out.shift_px += d;
        out.travel_m += s;
        out.ok = true;
        out.H = Hc;
    }
    return out;
}

} // namespace hw
