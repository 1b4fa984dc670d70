// photometric.hpp - the smooth brightness change between a frame and the previous one warped onto it.
//
// Road alignment moves every road point to where it is now, but not its brightness: how bright a
// point of asphalt looks depends on where in the image it is seen (lens vignetting, and the sheen of
// the road toward a low sun, which grows at grazing angles), and the warp carries the brightness of
// the point's old image position along. On the real motorway frames (TME tme08, against the light) the
// warped previous frame is 8-10 gray levels brighter than the current one near the bottom, while the
// unaligned difference does not see this at all (there the same image positions are compared), so a
// well aligned road looked worse aligned than not at all (7.9 against 5.6 gray levels).
// The change is smooth over the image, so it is modelled per frame as a quadratic surface
//     o(x, y) = c0 + c1 u + c2 v + c3 u^2 + c4 u v + c5 v^2,   u = x / sx - 1, v = y / sy - 1
// (sx, sy = half the image size), fitted by least squares to the mean signed difference
// I_k - warp(I_{k-1}) of the road cells, with trimming passes that drop the cells far from the
// surface (vehicles, whose difference is what we look for); the compensated difference is then
// |I_k - warp(I_{k-1}) - o(x, y)|.
#pragma once

#include <opencv2/core.hpp>

#include <array>

namespace hw {

struct BrightnessSurface {
    bool ok = false;
    std::array<double, 6> c{};   // coefficients of o(x, y), gray levels
    double sx = 1.0, sy = 1.0;   // px; u = x / sx - 1, v = y / sy - 1
    double at(double x, double y) const {
        const double u = x / sx - 1.0, v = y / sy - 1.0;
        return c[0] + c[1] * u + c[2] * v + c[3] * u * u + c[4] * u * v + c[5] * v * v;
    }
};

// Fits o(x, y) to the signed difference `d` (CV_16SC1, cur - warped) on the cells of size cell_w x
// cell_h of which at least half the pixels are non-zero in `mask` (CV_8UC1, same size as d; an empty
// mask = every cell), each cell at the mean of d over its masked pixels. trim: cells farther than trim x 1.4826 MAD (+ 1 gray level) from the surface are dropped
// and the fit repeated (3 passes). Fewer than 12 cells: ok = false.
BrightnessSurface fit_brightness_surface(const cv::Mat &d, const cv::Mat &mask, int cell_w, int cell_h, double trim);

// The same fit from cell means already computed: `means` (CV_32FC1) holds the mean signed difference
// of cells cell_w x cell_h px (cell (r, c) centred at ((c + 0.5) cell_w, (r + 0.5) cell_h)), `use`
// (CV_8UC1, same size) the cells to fit on; `image` the size the surface's coordinates refer to.
BrightnessSurface fit_brightness_cells(const cv::Mat &means, const cv::Mat &use, double cell_w, double cell_h,
                                       cv::Size image, double trim);

// |d - o(x, y)| saturated to CV_8UC1 (d as above); o = 0 when !s.ok.
void compensated_absdiff(const cv::Mat &d, const BrightnessSurface &s, cv::Mat &out);

// Mean |d - o| over the non-zero pixels of mask (NaN for none).
double compensated_mean(const cv::Mat &d, const BrightnessSurface &s, const cv::Mat &mask);

} // namespace hw
