#include "detect/cascade/haar_cascade.hpp"

#include <opencv2/imgproc.hpp>

#include <immintrin.h>

#include <algorithm>
#include <cmath>
#include <sstream>
#include <stdexcept>

namespace hw {

namespace {

const float kThresholdEps = 1e-5f;  // OpenCV lowers every stage threshold by this when it reads the XML

[[noreturn]] void bad(const std::string &path, const std::string &why) {
    throw std::invalid_argument("cascade.model: '" + path + "' " + why +
                                "; train one with `headway train cascade` or leave the key empty");
}

std::vector<float> numbers(const cv::FileNode &n) {
    std::vector<float> v;
    if (n.isSeq())
        for (const auto &e : n) v.push_back(float(double(e)));
    else if (n.isString()) {  // "0 -1 373 -0.032" written as one string by some writers
        std::istringstream is{std::string(n)};
        for (double d; is >> d;) v.push_back(float(d));
    } else if (n.isReal() || n.isInt())
        v.push_back(float(double(n)));
    return v;
}

} // namespace

HaarCascade::HaarCascade(const std::string &path, int lanes) {
    cv::FileStorage fs;
    try {
        fs.open(path, cv::FileStorage::READ);
    } catch (const cv::Exception &e) {
        bad(path, std::string("cannot be parsed (") + e.what() + ")");
    }
    if (!fs.isOpened()) bad(path, "cannot be opened");
    const cv::FileNode root = fs.getFirstTopLevelNode();
    if (std::string(root["stageType"]) != "BOOST" || std::string(root["featureType"]) != "HAAR")
        bad(path, "is not an OpenCV cascade with stageType BOOST and featureType HAAR (new format)");
    win_ = cv::Size(int(root["width"]), int(root["height"]));
    if (win_.width < 3 || win_.height < 3) bad(path, "has no window size");
    for (const auto &fn : root["features"]) {
        if (!fn["tilted"].empty() && int(fn["tilted"]) != 0)
            bad(path, "has tilted features, which only OpenCV's scan runs (cascade.opencv_scan: true)");
        Feature f{};
        for (const auto &rn : fn["rects"]) {
            const std::vector<float> v = numbers(rn);
            if (v.size() != 5 || f.n >= 3) bad(path, "has a feature rectangle that is not x y w h weight");
            f.r[f.n++] = {int(v[0]), int(v[1]), int(v[2]), int(v[3]), v[4]};
        }
        if (f.n < 2) bad(path, "has a feature with fewer than two rectangles");
        features_.push_back(f);
    }
    for (const auto &sn : root["stages"]) {
        Stage st{int(stumps_.size()), 0, float(double(sn["stageThreshold"])) - kThresholdEps};
        for (const auto &wn : sn["weakClassifiers"]) {
            const std::vector<float> in = numbers(wn["internalNodes"]), leaves = numbers(wn["leafValues"]);
            if (in.size() != 4 || leaves.size() != 2) bad(path, "has a weak classifier that is not a stump");
            const int fi = int(in[2]);
            if (fi < 0 || fi >= int(features_.size())) bad(path, "refers to a feature it does not define");
            stumps_.push_back({fi, in[3], leaves[0], leaves[1]});
            ++st.count;
        }
        if (st.count == 0) bad(path, "has a stage without weak classifiers");
        stages_.push_back(st);
    }
    if (stages_.empty()) bad(path, "has no stages");
    const bool has_avx2 = __builtin_cpu_supports("avx2");
    if (lanes != 0 && lanes != 4 && lanes != 8)
        throw std::invalid_argument("cascade.scan_lanes: " + std::to_string(lanes) + " is not 0 (the widest), 4 or 8");
    if (lanes == 8 && !has_avx2)
        throw std::invalid_argument("cascade.scan_lanes: 8 needs a CPU with AVX2, which this one lacks; use 0 or 4");
    avx2_ = lanes == 8 || (lanes == 0 && has_avx2);
}

void HaarCascade::layout(int step, int plane_len) const {
    if (step == laid_step_ && plane_len == laid_len_) return;
    // Corner (cx, cy) of a window whose top-left integral entry is (x, y) = (step j, y) lies in plane cx % step at
    // column j + cx / step of integral row y + cy: offset cy * step * L + (cx % step) * L + cx / step from the
    // window's entry (plane 0, row y, column j). Rectangle (x, y, w, h): corners p0 = (x, y), p1 = (x + w, y),
    // p2 = (x, y + h), p3 = (x + w, y + h), its sum p0 - p1 - p2 + p3.
    auto corner = [step, plane_len](int cx, int cy) { return (cy * step + cx % step) * plane_len + cx / step; };
    auto corners = [&](int x, int y, int w, int h, int *o) {
        o[0] = corner(x, y); o[1] = corner(x + w, y); o[2] = corner(x, y + h); o[3] = corner(x + w, y + h);
    };
    nodes_.resize(stumps_.size());
    for (size_t i = 0; i < stumps_.size(); ++i) {
        const Feature &f = features_[size_t(stumps_[i].feature)];
        Node &n = nodes_[i];
        auto fill = [](float *v, float x) { std::fill(v, v + 4, x); };
        for (int k = 0; k < 3; ++k) {
            const Rect r = k < f.n ? f.r[k] : Rect{0, 0, 0, 0, 0.f};
            corners(r.x, r.y, r.w, r.h, n.ofs[k]);
            fill(n.w[k], r.weight);
        }
        n.three = f.n == 3 && f.r[2].weight != 0.f;  // OpenCV adds the third rectangle only when its weight is not 0
        fill(n.threshold, stumps_[i].threshold);
        fill(n.left, stumps_[i].left);
        fill(n.right, stumps_[i].right);
    }
    laid_step_ = step;
    laid_len_ = plane_len;
}

// Variance normalisation of the window whose top-left integral entries are `sum`, `sq` (row step `stride`):
// false when OpenCV does not classify it (flat window).
bool HaarCascade::norm_factor(const int *sum, const unsigned *sq, int stride, float &norm) const {
    const int o0 = stride + 1, o1 = stride + win_.width - 1, o2 = (win_.height - 1) * stride + 1,
              o3 = (win_.height - 1) * stride + win_.width - 1;  // OpenCV's normrect (1, 1, W - 2, H - 2)
    const int valsum = sum[o0] - sum[o1] - sum[o2] + sum[o3];
    const unsigned valsq = sq[o0] - sq[o1] - sq[o2] + sq[o3];
    const double area = double(win_.width - 2) * (win_.height - 2);
    double nf = area * valsq - double(valsum) * valsum;
    if (!(nf > 0.)) return false;
    nf = std::sqrt(nf);
    norm = float(1. / nf);
    return area * norm < 1e-1;
}

// OpenCV's predictOrderedStump on four windows at once (SSE2, the x86-64 baseline): lane k is the window whose
// plane entry is p + k. The same single-precision operations in the same order per lane, and each lane's stage sum
// accumulated in double in stump order, so every lane decides exactly as the scalar code does. `alive`: lanes to
// classify (bit k). Returns the lanes every stage accepts; `rejected_first`: lanes the first stage rejects;
// `sums`: the last stage's sum per accepted lane.
int HaarCascade::classify4(const int *p, const float *norm, int alive, int &rejected_first, double *sums) const {
    const __m128 nv = _mm_loadu_ps(norm);
    auto rect_sum = [p](const int *o) {
        __m128i s = _mm_sub_epi32(_mm_loadu_si128((const __m128i *)(p + o[0])), _mm_loadu_si128((const __m128i *)(p + o[1])));
        s = _mm_sub_epi32(s, _mm_loadu_si128((const __m128i *)(p + o[2])));
        s = _mm_add_epi32(s, _mm_loadu_si128((const __m128i *)(p + o[3])));
        return _mm_cvtepi32_ps(s);
    };
    const Node *node = nodes_.data();
    __m128d lo = _mm_setzero_pd(), hi = _mm_setzero_pd();
    rejected_first = 0;
    for (size_t s = 0; s < stages_.size() && alive; ++s) {
        const Stage &st = stages_[s];
        lo = _mm_setzero_pd(); hi = _mm_setzero_pd();
        for (const Node *end = node + st.count; node != end; ++node) {
            __m128 r = _mm_add_ps(_mm_mul_ps(_mm_load_ps(node->w[0]), rect_sum(node->ofs[0])),
                                  _mm_mul_ps(_mm_load_ps(node->w[1]), rect_sum(node->ofs[1])));
            if (node->three) r = _mm_add_ps(r, _mm_mul_ps(_mm_load_ps(node->w[2]), rect_sum(node->ofs[2])));
            const __m128 m = _mm_cmplt_ps(_mm_mul_ps(r, nv), _mm_load_ps(node->threshold));  // f < threshold: left
            const __m128 leaf = _mm_or_ps(_mm_and_ps(m, _mm_load_ps(node->left)), _mm_andnot_ps(m, _mm_load_ps(node->right)));
            lo = _mm_add_pd(lo, _mm_cvtps_pd(leaf));
            hi = _mm_add_pd(hi, _mm_cvtps_pd(_mm_movehl_ps(leaf, leaf)));
        }
        const __m128d th = _mm_set1_pd(double(st.threshold));
        const int rej = _mm_movemask_pd(_mm_cmplt_pd(lo, th)) | (_mm_movemask_pd(_mm_cmplt_pd(hi, th)) << 2);
        if (s == 0) rejected_first = rej & alive;
        alive &= ~rej;
    }
    _mm_storeu_pd(sums, lo);
    _mm_storeu_pd(sums + 2, hi);
    return alive;
}

// classify4 on eight windows at once with AVX2 (used when the CPU has it; the same operations per lane, no FMA).
__attribute__((target("avx2"))) int HaarCascade::classify8(const int *p, const float *norm, int alive,
                                                           int &rejected_first, double *sums) const {
    const __m256 nv = _mm256_loadu_ps(norm);
    auto rect_sum = [p](const int *o) __attribute__((target("avx2"))) {
        __m256i s = _mm256_sub_epi32(_mm256_loadu_si256((const __m256i *)(p + o[0])),
                                     _mm256_loadu_si256((const __m256i *)(p + o[1])));
        s = _mm256_sub_epi32(s, _mm256_loadu_si256((const __m256i *)(p + o[2])));
        s = _mm256_add_epi32(s, _mm256_loadu_si256((const __m256i *)(p + o[3])));
        return _mm256_cvtepi32_ps(s);
    };
    const Node *node = nodes_.data();
    __m256d lo = _mm256_setzero_pd(), hi = _mm256_setzero_pd();
    rejected_first = 0;
    for (size_t s = 0; s < stages_.size() && alive; ++s) {
        const Stage &st = stages_[s];
        lo = _mm256_setzero_pd(); hi = _mm256_setzero_pd();
        for (const Node *end = node + st.count; node != end; ++node) {
            __m256 r = _mm256_add_ps(_mm256_mul_ps(_mm256_broadcast_ss(node->w[0]), rect_sum(node->ofs[0])),
                                     _mm256_mul_ps(_mm256_broadcast_ss(node->w[1]), rect_sum(node->ofs[1])));
            if (node->three) r = _mm256_add_ps(r, _mm256_mul_ps(_mm256_broadcast_ss(node->w[2]), rect_sum(node->ofs[2])));
            const __m256 m = _mm256_cmp_ps(_mm256_mul_ps(r, nv), _mm256_broadcast_ss(node->threshold), _CMP_LT_OQ);
            const __m256 leaf = _mm256_blendv_ps(_mm256_broadcast_ss(node->right), _mm256_broadcast_ss(node->left), m);
            lo = _mm256_add_pd(lo, _mm256_cvtps_pd(_mm256_castps256_ps128(leaf)));
            hi = _mm256_add_pd(hi, _mm256_cvtps_pd(_mm256_extractf128_ps(leaf, 1)));
        }
        const __m256d th = _mm256_set1_pd(double(st.threshold));
        const int rej = _mm256_movemask_pd(_mm256_cmp_pd(lo, th, _CMP_LT_OQ)) |
                        (_mm256_movemask_pd(_mm256_cmp_pd(hi, th, _CMP_LT_OQ)) << 4);
        if (s == 0) rejected_first = rej & alive;
        alive &= ~rej;
    }
    _mm256_storeu_pd(sums, lo);
    _mm256_storeu_pd(sums + 4, hi);
    return alive;
}

void HaarCascade::scan(const cv::Mat &img, int step, std::vector<HaarWindow> &out) const {
    CV_Assert(img.type() == CV_8UC1 && step >= 1);
    if (img.cols <= win_.width || img.rows <= win_.height) return;
    cv::integral(img, sum_, sqsum_, CV_32S, CV_32S);
    CV_Assert(sum_.isContinuous() && sqsum_.isContinuous() && sum_.step == sqsum_.step);
    const int stride = sum_.cols;
    // The integral split by column into `step` planes, plane m holding columns m, m + step, m + 2 step ...: the
    // windows x = step j, step (j + 1) ... of a row then read each corner from four consecutive entries.
    // + 8: the last block of a row reads past its end; never shorter than before, so that the stumps are laid out
    // again only when a wider band comes (once or twice a run)
    const int plane_len = step == laid_step_ ? std::max(laid_len_, (stride + step - 1) / step + 8) : (stride + step - 1) / step + 8;
    planes_.resize(size_t(sum_.rows) * step * plane_len);
    for (int r = 0; r < sum_.rows; ++r) {
        const int *src = sum_.ptr<int>(r);
        for (int m = 0; m < step; ++m) {
            int *dst = planes_.data() + (size_t(r) * step + m) * plane_len;
            int j = 0;
            for (int c = m; c < stride; c += step) dst[j++] = src[c];
            std::fill(dst + j, dst + plane_len, 0);
        }
    }
    layout(step, plane_len);
    // OpenCV's rows: its working size is (cols + 1 - W, rows + 1 - H), cut into ceil(width / 32) stripes of whole
    // steps, ((height / step + stripes - 1) / stripes) steps each (integer division): the last row of the working
    // size is left out when the stripes do not reach it. Reproduced so that step 2 scans OpenCV's windows.
    const int ww = img.cols + 1 - win_.width, wh = img.rows + 1 - win_.height;
    const int stripes = (ww + 31) / 32, stripe = std::max((wh / step + stripes - 1) / stripes, 1) * step;
    const int yend = std::min(stripes * stripe, wh);
    const int nx = (ww + step - 1) / step;  // windows x = step j < ww of a row
    const int lanes = avx2_ ? 8 : 4;
    float norm[8];
    double sums[8];
    for (int y = 0; y < yend; y += step) {
        const int *srow = sum_.ptr<int>(y);
        const unsigned *qrow = sqsum_.ptr<unsigned>(y);
        const int *prow = planes_.data() + size_t(y) * step * plane_len;
        bool skip = false;  // OpenCV skips the next window after one the first stage rejects
        for (int j0 = 0; j0 < nx; j0 += lanes) {
            int ok = 0;
            for (int k = 0; k < lanes; ++k) {
                norm[k] = 1.f;
                if (j0 + k < nx && norm_factor(srow + step * (j0 + k), qrow + step * (j0 + k), stride, norm[k])) ok |= 1 << k;
            }
            int first = 0, accepted = 0;
            if (ok) accepted = avx2_ ? classify8(prow + j0, norm, ok, first, sums) : classify4(prow + j0, norm, ok, first, sums);
            for (int k = 0; k < lanes && j0 + k < nx; ++k) {
                if (skip) { skip = false; continue; }  // not scanned by OpenCV
                if (first >> k & 1) skip = true;
                else if (accepted >> k & 1) out.push_back({step * (j0 + k), y, sums[k]});
            }
        }
    }
}

} // namespace hw
