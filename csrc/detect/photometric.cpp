#include "detect/photometric.hpp"

#include <opencv2/imgproc.hpp>

#include <algorithm>
#include <cmath>
#include <vector>

namespace hw {

namespace {
struct Sample { double x, y, v; };

BrightnessSurface fit_samples(const std::vector<Sample> &cells, cv::Size image, double trim) {
    BrightnessSurface s;
    s.sx = 0.5 * image.width;
    s.sy = 0.5 * image.height;
    if (cells.size() < 12) return s;
    std::vector<char> keep(cells.size(), 1);
    std::vector<double> res(cells.size()), kept_abs;
    for (int pass = 0; pass < 3; ++pass) {
        // Normal equations A^T A c = A^T v over the kept cells, A = [1 u v u^2 uv v^2].
        cv::Matx66d AtA = cv::Matx66d::zeros();
        cv::Vec6d Atb = cv::Vec6d::all(0.0);
        int n = 0;
        for (size_t i = 0; i < cells.size(); ++i) {
            if (!keep[i]) continue;
            const double u = cells[i].x / s.sx - 1.0, v = cells[i].y / s.sy - 1.0;
            const double a[6] = {1.0, u, v, u * u, u * v, v * v};
            for (int r = 0; r < 6; ++r) {
                for (int c = r; c < 6; ++c) AtA(r, c) += a[r] * a[c];
                Atb[r] += a[r] * cells[i].v;
            }
            ++n;
        }
        if (n < 12) return s;
        for (int r = 0; r < 6; ++r)
            for (int c = 0; c < r; ++c) AtA(r, c) = AtA(c, r);
        cv::Vec6d c;
        if (!cv::solve(AtA, Atb, c, cv::DECOMP_CHOLESKY) && !cv::solve(AtA, Atb, c, cv::DECOMP_SVD)) return s;
        for (int k = 0; k < 6; ++k) s.c[size_t(k)] = c[k];
        s.ok = true;
        // Trim: cells farther than trim robust sigmas from the surface (the robust sigma from the
        // kept cells' median absolute residual).
        kept_abs.clear();
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
} // namespace

BrightnessSurface fit_brightness_surface(const cv::Mat &d, const cv::Mat &mask, int cell_w, int cell_h, double trim) {
    CV_Assert(d.type() == CV_16SC1 && cell_w > 0 && cell_h > 0);
    CV_Assert(mask.empty() || (mask.type() == CV_8UC1 && mask.size() == d.size()));
    // Cell means of the signed difference over the masked pixels.
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
    return fit_samples(cells, d.size(), trim);
}

BrightnessSurface fit_brightness_cells(const cv::Mat &means, const cv::Mat &use, double cell_w, double cell_h,
                                       cv::Size image, double trim) {
    CV_Assert(means.type() == CV_32FC1 && use.type() == CV_8UC1 && use.size() == means.size());
    std::vector<Sample> cells;
    for (int r = 0; r < means.rows; ++r) {
        const float *m = means.ptr<float>(r);
        const uint8_t *u = use.ptr<uint8_t>(r);
        for (int c = 0; c < means.cols; ++c)
            if (u[c]) cells.push_back({(c + 0.5) * cell_w, (r + 0.5) * cell_h, double(m[c])});
    }
    return fit_samples(cells, image, trim);
}

void compensated_absdiff(const cv::Mat &d, const BrightnessSurface &s, cv::Mat &out) {
    CV_Assert(d.type() == CV_16SC1);
    if (!s.ok) {
        cv::Mat a = cv::abs(d);
        a.convertTo(out, CV_8U);
        return;
    }
    // o is smooth: evaluated on a grid of 8 x 8 px nodes and interpolated bilinearly (OpenCV's vectorised
    // resize), to well under a gray level; then |d - o| with vectorised 16-bit arithmetic.
    const int step = 8, gx = d.cols / step + 2, gy = d.rows / step + 2;
    cv::Mat grid(gy, gx, CV_32F);
    for (int r = 0; r < gy; ++r)
        for (int c = 0; c < gx; ++c) grid.at<float>(r, c) = float(s.at((c - 0.5) * step + 0.5 * (step - 1), (r - 0.5) * step + 0.5 * (step - 1)));
    cv::Mat o, o16, a;
    cv::resize(grid, o, cv::Size(gx * step, gy * step), 0, 0, cv::INTER_LINEAR);
    o(cv::Rect(step / 2, step / 2, d.cols, d.rows)).convertTo(o16, CV_16S);
    cv::absdiff(d, o16, a);
    a.convertTo(out, CV_8U);
}

double compensated_mean(const cv::Mat &d, const BrightnessSurface &s, const cv::Mat &mask) {
    CV_Assert(mask.type() == CV_8UC1 && mask.size() == d.size());
    cv::Mat a;
    compensated_absdiff(d, s, a);
    const int n = cv::countNonZero(mask);
    return n ? cv::sum(a & mask)[0] / n : NAN;
}

} // namespace hw
