// haar_cascade.hpp - a stump-based Haar cascade (OpenCV's cascade XML, `stageType BOOST`, `featureType HAAR`,
// upright features) evaluated at every window of one image, with exactly the arithmetic of OpenCV 4's
// HaarEvaluator and predictOrderedStump, so that it accepts the windows cv::CascadeClassifier accepts, with the
// same last-stage sums (tests/test_cascade_detect.py compares the detections on real and rendered images):
//  - the integral image I and the integral of squares Q of the image (32-bit; the window sums are exact);
//  - per window at (x, y), over the window less a one-pixel border (A = (W-2)(H-2) pixels):
//        nf = A * sum(Q) - sum(I)^2,  n = (float)(1 / sqrt(nf)),
//    and the window is never classified when nf <= 0 or A * n >= 0.1 (grey-level standard deviation <= 10);
//  - feature response in single precision, in this order:  f = (w0 S(r0) + w1 S(r1) [+ w2 S(r2)]) * n,
//    S(r) the rectangle's pixel sum (four lookups), the third term only when w2 != 0;
//  - stump: leaf `left` when f < threshold, else `right`; stage: the double-precision sum of its leaves must
//    reach (float)stageThreshold - 1e-5f (OpenCV's THRESHOLD_EPS), else the window is rejected there.
// Scan (OpenCV's CascadeClassifierInvoker at one scale): rows y = 0, step, 2 step ... (OpenCV's row stripes can
// leave out the last row: reproduced, see scan()); along a row x = 0, step ..., and after a window that the
// *first* stage rejects the next position is skipped (OpenCV's `x += yStep`). With step 2 these are exactly the
// windows OpenCV's detectMultiScale scans at scale 1.
//
// Why not cv::CascadeClassifier (measured, docs/decisions.md): the same windows cost 4x less here.
// OpenCV picks each stump's leaf by a branch on a comparison that goes either way from window to window, and
// evaluates one window at a time; here the leaf is selected without a branch and four (SSE2) or eight (AVX2, where the CPU
// has it) consecutive windows of a row are evaluated together, from the integral split into column planes so
// that each rectangle corner of the eight windows is one load. The scan step is a parameter (OpenCV's is 2).
#pragma once

#include <opencv2/core.hpp>

#include <string>
#include <vector>

namespace hw {

struct HaarWindow {
    int x = 0, y = 0;    // px, top-left corner of the window in the scanned image
    double stage_sum = 0;  // the last stage's sum of leaves (OpenCV's levelWeights)
};

class HaarCascade {
public:
    // Reads an OpenCV cascade XML (new format, stumps, upright Haar features). `lanes`: windows evaluated at once,
    // 4 (SSE2), 8 (AVX2) or 0 = the widest the CPU has. Throws std::invalid_argument naming what is missing or
    // unsupported.
    explicit HaarCascade(const std::string &path, int lanes = 0);

    cv::Size window() const { return win_; }
    int stages() const { return int(stages_.size()); }

    // Every window of `img` (CV_8UC1) on the grid of `step` px that all stages accept, appended to `out` in
    // row-major order. Not thread-safe (the integral buffers are members).
    void scan(const cv::Mat &img, int step, std::vector<HaarWindow> &out) const;

private:
    struct Rect { int x, y, w, h; float weight; };
    struct Feature { Rect r[3]; int n; };
    struct Stump { int feature; float threshold, left, right; };
    struct Stage { int first, count; float threshold; };
    // One stump laid out for the column planes of an integral image (scan()): corner offsets of its three
    // rectangles (sum = p0 - p1 - p2 + p3), and its weights, threshold and leaves repeated for the four lanes.
    struct alignas(16) Node {
        float w[3][4];
        float threshold[4], left[4], right[4];
        int ofs[3][4];
        bool three;  // the third rectangle counts (weight not 0)
    };

    void layout(int step, int plane_len) const;
    bool norm_factor(const int *sum, const unsigned *sq, int stride, float &norm) const;
    int classify4(const int *p, const float *norm, int alive, int &rejected_first, double *sums) const;
    int classify8(const int *p, const float *norm, int alive, int &rejected_first, double *sums) const;

    cv::Size win_;
    bool avx2_ = false;  // eight windows at once (classify8) where the CPU has AVX2
    std::vector<Feature> features_;
    std::vector<Stump> stumps_;
    std::vector<Stage> stages_;
    mutable std::vector<Node> nodes_;  // stumps_ laid out for planes of laid_step_ x laid_len_
    mutable int laid_step_ = -1, laid_len_ = -1;
    mutable cv::Mat sum_, sqsum_;      // integral images (CV_32S), reused between calls
    mutable std::vector<int> planes_;  // sum_ split by column into `step` planes (scan())
};

} // namespace hw
