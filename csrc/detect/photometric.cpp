#include "detect/photometric.hpp"

#include <algorithm>
#include <cmath>
#include <vector>

namespace hw {

BrightnessSurface fit_brightness_surface(const cv::Mat &d, const cv::Mat &mask, int cell_w, int cell_h, double trim) {
    CV_Assert(d.type() == CV_16SC1 && cell_w > 0 && cell_h > 0);
    CV_Assert(mask.empty() || (mask.type() == CV_8UC1 && mask.size() == d.size()));
    BrightnessSurface s;
    s.sx = 0.5 * d.cols;
    s.sy = 0.5 * d.rows;
    // Cell means of the signed difference over the masked pixels.
    struct Sample { double x, y, v; };
    std::vector<Sample> cells;
    for (int y0 = 0; y0 + cell_h <= d.rows; y0 += cell_h)
        for (int x0 = 0; x0 + cell_w <= d.cols; x0 += cell_w) {
            long sum = 0;
            int n = 0;
            for (int y = y0; y < y0 + cell_h; ++y) {
                const int16_t *r = d.ptr<int16_t>(y);
                const uint8_t *m = mask.empty() ? nullptr : mask.ptr<uint8_t>(y);
                for (int x = x0; x < x0 + cell_w; ++x)
                    if (!m || m[x]) { sum += r[x]; ++n; }
            }
            if (2 * n >= cell_w * cell_h) cells.push_back({x0 + 0.5 * cell_w, y0 + 0.5 * cell_h, double(sum) / n});
        }
    if (cells.size() < 12) return s;
    std::vector<char> keep(cells.size(), 1);
    std::vector<double> res(cells.size());
    for (int pass = 0; pass < 3; ++pass) {
        // Normal equations A^T A c = A^T v over the kept cells, A = [1 u v u^2 uv v^2].
        cv::Matx66d AtA = cv::Matx66d::zeros();
        cv::Vec6d Atb = cv::Vec6d::all(0.0);
        int n = 0;
        for (size_t i = 0; i < cells.size(); ++i) {
            if (!keep[i]) continue;
            const double u = cells[i].x / s.sx - 1.0, v = cells[i].y / s.sy - 1.0;
            const cv::Vec6d a(1.0, u, v, u * u, u * v, v * v);
            AtA += a * a.t();
            Atb += a * cells[i].v;
            ++n;
        }
        if (n < 12) return s;
        cv::Vec6d c;
        if (!cv::solve(AtA, Atb, c, cv::DECOMP_SVD)) return s;
        for (int k = 0; k < 6; ++k) s.c[size_t(k)] = c[k];
        s.ok = true;
        // Trim: cells farther than trim robust sigmas from the surface (the robust sigma from the
        // kept cells' median absolute residual).
        std::vector<double> kept_abs;
        for (size_t i = 0; i < cells.size(); ++i) {
            res[i] = std::fabs(cells[i].v - s.at(cells[i].x, cells[i].y));
            if (keep[i]) kept_abs.push_back(res[i]);
        }
        std::nth_element(kept_abs.begin(), kept_abs.begin() + long(kept_abs.size() / 2), kept_abs.end());
        const double lim = trim * 1.4826 * kept_abs[kept_abs.size() / 2] + 1.0;
        for (size_t i = 0; i < cells.size(); ++i) keep[i] = res[i] <= lim;
    }
    return s;
}

void compensated_absdiff(const cv::Mat &d, const BrightnessSurface &s, cv::Mat &out) {
    CV_Assert(d.type() == CV_16SC1);
    out.create(d.size(), CV_8UC1);
    std::vector<float> o(size_t(d.cols));
    for (int y = 0; y < d.rows; ++y) {
        const int16_t *r = d.ptr<int16_t>(y);
        uint8_t *w = out.ptr<uint8_t>(y);
        if (s.ok) {
            // o along the row is a quadratic in u: o = a + b u + c3 u^2.
            const double v = y / s.sy - 1.0;
            const double a = s.c[0] + s.c[2] * v + s.c[5] * v * v, b = s.c[1] + s.c[4] * v;
            for (int x = 0; x < d.cols; ++x) {
                const double u = x / s.sx - 1.0;
                o[size_t(x)] = float(a + (b + s.c[3] * u) * u);
            }
        } else {
            std::fill(o.begin(), o.end(), 0.f);
        }
        for (int x = 0; x < d.cols; ++x) w[x] = cv::saturate_cast<uint8_t>(std::fabs(float(r[x]) - o[size_t(x)]));
    }
}

double compensated_mean(const cv::Mat &d, const BrightnessSurface &s, const cv::Mat &mask) {
    CV_Assert(mask.type() == CV_8UC1 && mask.size() == d.size());
    cv::Mat a;
    compensated_absdiff(d, s, a);
    const int n = cv::countNonZero(mask);
    return n ? cv::sum(a & mask)[0] / n : NAN;
}

} // namespace hw
