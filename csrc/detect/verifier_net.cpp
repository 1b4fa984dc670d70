#include "detect/verifier_net.hpp"
#include "base/worker_pool.hpp"

#include <immintrin.h>
#include <opencv2/core/utility.hpp>

#include <algorithm>
#include <cmath>
#include <string>

namespace hw {

namespace {

// The layer of `net` made from the ONNX node with output `node`: OpenCV names it after that output, alone (4.6) or
// behind a prefix ("onnx_node_output_0!c0", later versions).
cv::Ptr<cv::dnn::Layer> layer_of(cv::dnn::Net &net, const std::string &node) {
    const std::string tail = "!" + node;
    for (const std::string &name : net.getLayerNames()) {
        const bool match = name == node || (name.size() > tail.size() &&
                                            name.compare(name.size() - tail.size(), tail.size(), tail) == 0);
        if (match) return net.getLayer(net.getLayerId(name));
    }
    return nullptr;
}

// blob k of a layer as floats, or empty when it is not there or not of `total` values
std::vector<float> blob(const cv::Ptr<cv::dnn::Layer> &l, size_t k, size_t total) {
    if (!l || l->blobs.size() <= k || l->blobs[k].type() != CV_32F || l->blobs[k].total() != total) return {};
    const cv::Mat m = l->blobs[k].isContinuous() ? l->blobs[k] : l->blobs[k].clone();
    return std::vector<float>(m.ptr<float>(), m.ptr<float>() + total);
}

// ---- one conv row: `row` (W x cout) = conv3x3 at output row y, `in` pointing at padded row y (the one above it) ----

void conv_row_plain(const float *in, int inw, int W, int cin, const float *w, int cout, float *row) {
    const int taps = 3 * cin;  // one kernel row: 3 columns x cin channels, contiguous in the padded map
    for (int x = 0; x < W; ++x) {
        float *o = row + size_t(x) * cout;
        std::fill(o, o + cout, 0.f);
        for (int ky = 0; ky < 3; ++ky) {
            const float *ip = in + (size_t(ky) * inw + x) * cin;
            const float *wp = w + size_t(ky) * taps * cout;
            for (int j = 0; j < taps; ++j) {
                const float v = ip[j];
                const float *wj = wp + size_t(j) * cout;
                for (int c = 0; c < cout; ++c) o[c] += v * wj[c];
            }
        }
    }
}

// C (6 rows x 16 columns, row stride ldc) = sum over `segments` of A_s (6 rows, `astride` apart, k values each) x B_s
// (k rows, ldb apart), A_s and B_s each segment `aseg` and `bseg` floats further on: twelve accumulators (enough in
// flight for two FMA ports of 4-5 cycles' latency), each B vector loaded once for the six rows. A convolution row is
// this with the kernel's 3 rows as segments (rows of A: output pixels, cin apart; k: 3 columns x cin channels), a
// Winograd position one segment. Named variables, not an array: GCC 12 keeps an array of __m256 on the stack and
// stores it every step.
__attribute__((target("avx2,fma"))) inline void mac6x16(const float *a, int astride, int k, int segments, size_t aseg,
                                                         const float *b, int ldb, size_t bseg, float *c, int ldc) {
    __m256 a0 = _mm256_setzero_ps(), a1 = a0, a2 = a0, a3 = a0, a4 = a0, a5 = a0;
    __m256 b0 = a0, b1 = a0, b2 = a0, b3 = a0, b4 = a0, b5 = a0;
    for (int sg = 0; sg < segments; ++sg) {
        const float *ip = a + sg * aseg, *wp = b + sg * bseg;
        for (int j = 0; j < k; ++j, wp += ldb) {
            const __m256 w0 = _mm256_loadu_ps(wp), w1 = _mm256_loadu_ps(wp + 8);
            __m256 v = _mm256_broadcast_ss(ip + j);
            a0 = _mm256_fmadd_ps(v, w0, a0); b0 = _mm256_fmadd_ps(v, w1, b0);
            v = _mm256_broadcast_ss(ip + j + astride);
            a1 = _mm256_fmadd_ps(v, w0, a1); b1 = _mm256_fmadd_ps(v, w1, b1);
            v = _mm256_broadcast_ss(ip + j + 2 * astride);
            a2 = _mm256_fmadd_ps(v, w0, a2); b2 = _mm256_fmadd_ps(v, w1, b2);
            v = _mm256_broadcast_ss(ip + j + 3 * astride);
            a3 = _mm256_fmadd_ps(v, w0, a3); b3 = _mm256_fmadd_ps(v, w1, b3);
            v = _mm256_broadcast_ss(ip + j + 4 * astride);
            a4 = _mm256_fmadd_ps(v, w0, a4); b4 = _mm256_fmadd_ps(v, w1, b4);
            v = _mm256_broadcast_ss(ip + j + 5 * astride);
            a5 = _mm256_fmadd_ps(v, w0, a5); b5 = _mm256_fmadd_ps(v, w1, b5);
        }
    }
    _mm256_storeu_ps(c, a0); _mm256_storeu_ps(c + 8, b0); c += ldc;
    _mm256_storeu_ps(c, a1); _mm256_storeu_ps(c + 8, b1); c += ldc;
    _mm256_storeu_ps(c, a2); _mm256_storeu_ps(c + 8, b2); c += ldc;
    _mm256_storeu_ps(c, a3); _mm256_storeu_ps(c + 8, b3); c += ldc;
    _mm256_storeu_ps(c, a4); _mm256_storeu_ps(c + 8, b4); c += ldc;
    _mm256_storeu_ps(c, a5); _mm256_storeu_ps(c + 8, b5);
}

// 8 output channels from channel co for six output pixels (a channel count that is an odd multiple of 8)
__attribute__((target("avx2,fma"))) inline void conv_block6x8(const float *in, int inw, int x, int cin, const float *w,
                                                               int cout, int co, float *row) {
    __m256 a0 = _mm256_setzero_ps(), a1 = a0, a2 = a0, a3 = a0, a4 = a0, a5 = a0;
    const int taps = 3 * cin;
    for (int ky = 0; ky < 3; ++ky) {
        const float *ip = in + (size_t(ky) * inw + x) * cin;
        const float *wp = w + size_t(ky) * taps * cout + co;
        for (int j = 0; j < taps; ++j, wp += cout) {
            const __m256 w0 = _mm256_loadu_ps(wp);
            a0 = _mm256_fmadd_ps(_mm256_broadcast_ss(ip + j), w0, a0);
            a1 = _mm256_fmadd_ps(_mm256_broadcast_ss(ip + j + cin), w0, a1);
            a2 = _mm256_fmadd_ps(_mm256_broadcast_ss(ip + j + 2 * cin), w0, a2);
            a3 = _mm256_fmadd_ps(_mm256_broadcast_ss(ip + j + 3 * cin), w0, a3);
            a4 = _mm256_fmadd_ps(_mm256_broadcast_ss(ip + j + 4 * cin), w0, a4);
            a5 = _mm256_fmadd_ps(_mm256_broadcast_ss(ip + j + 5 * cin), w0, a5);
        }
    }
    float *o = row + size_t(x) * cout + co;
    _mm256_storeu_ps(o, a0); o += cout;
    _mm256_storeu_ps(o, a1); o += cout;
    _mm256_storeu_ps(o, a2); o += cout;
    _mm256_storeu_ps(o, a3); o += cout;
    _mm256_storeu_ps(o, a4); o += cout;
    _mm256_storeu_ps(o, a5);
}

__attribute__((target("avx2,fma"))) void conv_row_avx2(const float *in, int inw, int W, int cin, const float *w,
                                                        int cout, float *row) {
    // W is a multiple of 6 (the crop's width a multiple of 24, from_dnn)
    for (int co = 0; co + 16 <= cout; co += 16)
        for (int x = 0; x < W; x += 6)
            mac6x16(in + size_t(x) * cin, cin, 3 * cin, 3, size_t(inw) * cin, w + co, cout, size_t(3) * cin * cout,
                    row + size_t(x) * cout + co, cout);
    if (cout % 16)
        for (int x = 0; x < W; x += 6) conv_block6x8(in, inw, x, cin, w, cout, cout - 8, row);
}

// ---- Winograd F(2x2, 3x3) for the layers with 8 or more input channels (AVX2 path) ----
// A 2x2 output tile from its 4x4 input tile d: Y = A^T [(G g G^T) .* (B^T d B)] A, summed over the input channels, with
//     B^T = [1 0 -1 0; 0 1 1 0; 0 -1 1 0; 0 1 0 -1],  G = [1 0 0; .5 .5 .5; .5 -.5 .5; 0 0 1],  A^T = [1 1 1 0; 0 1 -1 -1]
// (Lavin and Gray 2016): 16 multiplies per tile and channel pair instead of 36, 2.25x fewer; the transforms are adds.
// The 2x2 output tile is one 2x2 pool window, so the pool is taken from the tile directly.

// V (16 positions x tiles x cin) of one row of tiles: `in` at the tiles' top padded row, tiles x 2 columns apart
__attribute__((target("avx2,fma"))) void winograd_input(const float *in, int inw, int tiles, int cin, float *V) {
    const size_t pos_stride = size_t(tiles) * cin;
    for (int t = 0; t < tiles; ++t)
        for (int c = 0; c < cin; c += 8) {
            __m256 d[4][4];
            for (int r = 0; r < 4; ++r)
                for (int q = 0; q < 4; ++q) d[r][q] = _mm256_loadu_ps(in + (size_t(r) * inw + 2 * t + q) * cin + c);
            __m256 u[4][4];  // B^T d: along the rows
            for (int q = 0; q < 4; ++q) {
                u[0][q] = _mm256_sub_ps(d[0][q], d[2][q]);
                u[1][q] = _mm256_add_ps(d[1][q], d[2][q]);
                u[2][q] = _mm256_sub_ps(d[2][q], d[1][q]);
                u[3][q] = _mm256_sub_ps(d[1][q], d[3][q]);
            }
            float *v = V + size_t(t) * cin + c;
            for (int r = 0; r < 4; ++r) {  // (B^T d) B: along the columns
                _mm256_storeu_ps(v + (4 * r + 0) * pos_stride, _mm256_sub_ps(u[r][0], u[r][2]));
                _mm256_storeu_ps(v + (4 * r + 1) * pos_stride, _mm256_add_ps(u[r][1], u[r][2]));
                _mm256_storeu_ps(v + (4 * r + 2) * pos_stride, _mm256_sub_ps(u[r][2], u[r][1]));
                _mm256_storeu_ps(v + (4 * r + 3) * pos_stride, _mm256_sub_ps(u[r][1], u[r][3]));
            }
        }
}

// One row of pooled outputs (tiles x cout, written at `out`) from the padded input rows at `in`: U (16 x cin x cout,
// cout a multiple of 16), tiles a multiple of 6; V and M scratch of 16 x tiles x cin and 16 x tiles x cout floats
__attribute__((target("avx2,fma"))) void winograd_row_pool(const float *in, int inw, int tiles, int cin, const float *U,
                                                            const float *bias, int cout, float *V, float *M, float *out) {
    winograd_input(in, inw, tiles, cin, V);
    for (int pos = 0; pos < 16; ++pos) {
        const float *v = V + size_t(pos) * tiles * cin, *u = U + size_t(pos) * cin * cout;
        float *m = M + size_t(pos) * tiles * cout;
        for (int co = 0; co < cout; co += 16)
            for (int t = 0; t < tiles; t += 6)
                mac6x16(v + size_t(t) * cin, cin, cin, 1, 0, u + co, cout, 0, m + size_t(t) * cout + co, cout);
    }
    const size_t ps = size_t(tiles) * cout;
    const __m256 zero = _mm256_setzero_ps();
    for (int t = 0; t < tiles; ++t)
        for (int co = 0; co < cout; co += 8) {
            const float *m = M + size_t(t) * cout + co;
            __m256 s[4][4];
            for (int r = 0; r < 4; ++r)
                for (int q = 0; q < 4; ++q) s[r][q] = _mm256_loadu_ps(m + (4 * r + q) * ps);
            __m256 w[2][4];  // A^T M: along the rows
            for (int q = 0; q < 4; ++q) {
                w[0][q] = _mm256_add_ps(_mm256_add_ps(s[0][q], s[1][q]), s[2][q]);
                w[1][q] = _mm256_sub_ps(_mm256_sub_ps(s[1][q], s[2][q]), s[3][q]);
            }
            __m256 mx[2];
            for (int r = 0; r < 2; ++r) {  // (A^T M) A: along the columns, and the pool's max of the four
                const __m256 y0 = _mm256_add_ps(_mm256_add_ps(w[r][0], w[r][1]), w[r][2]);
                const __m256 y1 = _mm256_sub_ps(_mm256_sub_ps(w[r][1], w[r][2]), w[r][3]);
                mx[r] = _mm256_max_ps(y0, y1);
            }
            const __m256 pooled = _mm256_max_ps(mx[0], mx[1]);
            _mm256_storeu_ps(out + size_t(t) * cout + co, _mm256_max_ps(_mm256_add_ps(pooled, _mm256_loadu_ps(bias + co)), zero));
        }
}

// ---- h = relu(W x + b): hidden a multiple of 8 ----

void dense_plain(const float *x, int nin, const float *w, const float *b, int hidden, float *h) {
    std::copy(b, b + hidden, h);
    for (int i = 0; i < nin; ++i) {
        const float v = x[i];
        const float *wi = w + size_t(i) * hidden;
        for (int j = 0; j < hidden; ++j) h[j] += v * wi[j];
    }
    for (int j = 0; j < hidden; ++j) h[j] = std::max(h[j], 0.f);
}

__attribute__((target("avx2,fma"))) void dense_avx2(const float *x, int nin, const float *w, const float *b, int hidden,
                                                     float *h) {
    for (int j0 = 0; j0 < hidden; j0 += 64) {  // 8 accumulators of 8 hidden units
        const int nv = std::min(8, (hidden - j0) / 8);
        __m256 acc[8];
        for (int v = 0; v < 8; ++v) acc[v] = v < nv ? _mm256_loadu_ps(b + j0 + 8 * v) : _mm256_setzero_ps();
        for (int i = 0; i < nin; ++i) {
            const __m256 a = _mm256_broadcast_ss(x + i);
            const float *wi = w + size_t(i) * hidden + j0;
            for (int v = 0; v < nv; ++v) acc[v] = _mm256_fmadd_ps(a, _mm256_loadu_ps(wi + 8 * v), acc[v]);
        }
        for (int v = 0; v < nv; ++v) _mm256_storeu_ps(h + j0 + 8 * v, _mm256_max_ps(acc[v], _mm256_setzero_ps()));
    }
}

// dense_avx2 for M crops at once (rows of x ldx apart, of h ldh apart; hidden a multiple of 16): each weight row is
// read once for the M crops instead of once a crop (the layer's ~0.4 MB of weights outgrow the L1 and L2 caches'
// share a crop gets). Every output is the same sum in the same order as dense_avx2's.
template <int M>
__attribute__((target("avx2,fma"))) void dense_rows_avx2(const float *x, size_t ldx, int nin, const float *w,
                                                          const float *b, int hidden, float *h, size_t ldh) {
    for (int j0 = 0; j0 < hidden; j0 += 16) {
        __m256 acc[M][2];
        for (int c = 0; c < M; ++c) {
            acc[c][0] = _mm256_loadu_ps(b + j0);
            acc[c][1] = _mm256_loadu_ps(b + j0 + 8);
        }
        for (int i = 0; i < nin; ++i) {
            const float *wi = w + size_t(i) * hidden + j0;
            const __m256 w0 = _mm256_loadu_ps(wi), w1 = _mm256_loadu_ps(wi + 8);
            for (int c = 0; c < M; ++c) {
                const __m256 a = _mm256_broadcast_ss(x + c * ldx + i);
                acc[c][0] = _mm256_fmadd_ps(a, w0, acc[c][0]);
                acc[c][1] = _mm256_fmadd_ps(a, w1, acc[c][1]);
            }
        }
        for (int c = 0; c < M; ++c) {
            _mm256_storeu_ps(h + c * ldh + j0, _mm256_max_ps(acc[c][0], _mm256_setzero_ps()));
            _mm256_storeu_ps(h + c * ldh + j0 + 8, _mm256_max_ps(acc[c][1], _mm256_setzero_ps()));
        }
    }
}

constexpr int kDenseGroup = 4;  // crops through the dense layer together (dense_rows_avx2)

// The dense layer for m <= kDenseGroup crops (rows of x ldx apart; h: m rows of `hidden`).
void dense_group(const float *x, size_t ldx, int m, int nin, const float *w, const float *b, int hidden, float *h,
                 bool avx2) {
    if (avx2 && hidden % 16 == 0) {
        switch (m) {
        case 4: dense_rows_avx2<4>(x, ldx, nin, w, b, hidden, h, size_t(hidden)); return;
        case 3: dense_rows_avx2<3>(x, ldx, nin, w, b, hidden, h, size_t(hidden)); return;
        case 2: dense_rows_avx2<2>(x, ldx, nin, w, b, hidden, h, size_t(hidden)); return;
        default: break;
        }
    }
    for (int c = 0; c < m; ++c) {
        if (avx2) dense_avx2(x + c * ldx, nin, w, b, hidden, h + size_t(c) * hidden);
        else dense_plain(x + c * ldx, nin, w, b, hidden, h + size_t(c) * hidden);
    }
}

} // namespace

std::unique_ptr<VerifierNet> VerifierNet::from_dnn(cv::dnn::Net &net, int crop_h, int crop_w) {
    if (crop_h % 8 || crop_h < 8 || crop_w % 24 || crop_w < 24) return nullptr;  // every map's width a multiple of 6 pixels
    auto n = std::unique_ptr<VerifierNet>(new VerifierNet);
    n->h_ = crop_h;
    n->w_ = crop_w;
    int cin = 1;
    for (int k = 0; k < 3; ++k) {
        const auto l = layer_of(net, "c" + std::to_string(k));
        if (!l || l->blobs.empty() || l->blobs[0].dims != 4) return nullptr;
        const cv::MatSize s = l->blobs[0].size;
        const int cout = s[0];
        if (s[1] != cin || s[2] != 3 || s[3] != 3 || cout % 8) return nullptr;
        const std::vector<float> w = blob(l, 0, size_t(cout) * cin * 9), b = blob(l, 1, size_t(cout));
        if (w.empty() || b.empty()) return nullptr;
        Conv &c = n->conv_[k];
        c.cin = cin;
        c.cout = cout;
        c.b = b;
        c.w.resize(w.size());
        for (int o = 0; o < cout; ++o)  // ONNX (cout, cin, ky, kx) -> (ky, kx, cin, cout)
            for (int i = 0; i < cin; ++i)
                for (int t = 0; t < 9; ++t) c.w[(size_t(t) * cin + i) * cout + o] = w[(size_t(o) * cin + i) * 9 + t];
        if (cin % 8 == 0 && cout % 16 == 0) {  // U = G g G^T of every channel pair, for winograd_row_pool
            c.wino.assign(size_t(16) * cin * cout, 0.f);
            static const double G[4][3] = {{1, 0, 0}, {0.5, 0.5, 0.5}, {0.5, -0.5, 0.5}, {0, 0, 1}};
            for (int o = 0; o < cout; ++o)
                for (int i = 0; i < cin; ++i) {
                    const float *g = &w[(size_t(o) * cin + i) * 9];
                    for (int r = 0; r < 4; ++r)
                        for (int q = 0; q < 4; ++q) {
                            double u = 0.0;
                            for (int ky = 0; ky < 3; ++ky)
                                for (int kx = 0; kx < 3; ++kx) u += G[r][ky] * g[ky * 3 + kx] * G[q][kx];
                            c.wino[(size_t(4 * r + q) * cin + i) * cout + o] = float(u);
                        }
                }
        }
        cin = cout;
    }
    const int h3 = crop_h / 8, w3 = crop_w / 8, c3 = cin, nflat = h3 * w3 * c3;
    const auto df = layer_of(net, "df"), de = layer_of(net, "de"), lo = layer_of(net, "logit");
    if (!df || df->blobs.empty() || df->blobs[0].dims != 2 || df->blobs[0].size[1] != nflat) return nullptr;
    const int hidden = df->blobs[0].size[0];
    if (hidden % 8 || hidden <= 0) return nullptr;
    const std::vector<float> wf = blob(df, 0, size_t(hidden) * nflat), bf = blob(df, 1, size_t(hidden));
    const std::vector<float> we = blob(de, 0, size_t(hidden) * 2), be = blob(de, 1, size_t(hidden));
    const std::vector<float> wo = blob(lo, 0, size_t(hidden)), bo = blob(lo, 1, 1);
    if (wf.empty() || bf.empty() || we.empty() || be.empty() || wo.empty() || bo.empty()) return nullptr;
    n->hidden_ = hidden;
    n->dense_w_.assign(size_t(nflat + 2) * hidden, 0.f);
    for (int j = 0; j < hidden; ++j) {
        for (int c = 0; c < c3; ++c)  // ONNX flattens (channel, row, column); the maps here are (row, column, channel)
            for (int y = 0; y < h3; ++y)
                for (int x = 0; x < w3; ++x)
                    n->dense_w_[(size_t(y * w3 + x) * c3 + c) * hidden + j] = wf[size_t(j) * nflat + (c * h3 + y) * w3 + x];
        n->dense_w_[size_t(nflat) * hidden + j] = we[size_t(j) * 2];
        n->dense_w_[size_t(nflat + 1) * hidden + j] = we[size_t(j) * 2 + 1];
    }
    n->dense_b_.resize(size_t(hidden));
    for (int j = 0; j < hidden; ++j) n->dense_b_[size_t(j)] = bf[size_t(j)] + be[size_t(j)];
    n->out_w_ = wo;
    n->out_b_ = bo[0];
    if (const auto bx = layer_of(net, "box")) {
        n->box_w_ = blob(bx, 0, size_t(4) * hidden);
        n->box_b_ = blob(bx, 1, 4);
        if (n->box_w_.empty() || n->box_b_.empty()) return nullptr;
    }
    n->avx2_ = __builtin_cpu_supports("avx2") && __builtin_cpu_supports("fma");
    return n;
}

void VerifierNet::forward(const float *crops, const float *extra, int n, float *p, float *box) const {
    constexpr int kPiece = 4;  // crops a piece of the work: fewer is not worth a thread
    const int pieces = (n + kPiece - 1) / kPiece;
    if (!pool_ || pool_->threads() <= 1 || pieces <= 1) {
        run(crops, extra, n, p, box, avx2_);
        return;
    }
    pool_->run(pieces, [&](int k, int) {  // base/worker_pool.hpp
        const int a = k * kPiece, b = std::min(n, a + kPiece);
        run(crops + size_t(a) * h_ * w_, extra + 2 * size_t(a), b - a, p + a, box ? box + 4 * size_t(a) : nullptr, avx2_);
    });
}

void VerifierNet::forward_plain(const float *crops, const float *extra, int n, float *p, float *box) const {
    run(crops, extra, n, p, box, false);
}

void VerifierNet::run(const float *crops, const float *extra, int n, float *p, float *box, bool avx2) const {
    // padded maps (zero border of one pixel): the input, and each layer's pooled output
    int hs[4] = {h_, h_ / 2, h_ / 4, h_ / 8}, ws[4] = {w_, w_ / 2, w_ / 4, w_ / 8};
    std::vector<float> maps[4];
    maps[0].assign(size_t(hs[0] + 2) * (ws[0] + 2), 0.f);
    size_t rowbuf = 0;
    for (int k = 0; k < 3; ++k) {
        maps[k + 1].assign(size_t(hs[k + 1] + 2) * (ws[k + 1] + 2) * conv_[k].cout, 0.f);
        rowbuf = std::max(rowbuf, size_t(ws[k]) * conv_[k].cout);
    }
    std::vector<float> rows(2 * rowbuf);
    size_t vlen = 0, mlen = 0;  // Winograd scratch: one row of tiles
    for (int k = 0; k < 3; ++k) {
        vlen = std::max(vlen, size_t(16) * ws[k + 1] * conv_[k].cin);
        mlen = std::max(mlen, size_t(16) * ws[k + 1] * conv_[k].cout);
    }
    std::vector<float> V(vlen), M(mlen);
    const int nflat = hs[3] * ws[3] * conv_[2].cout;
    const size_t ld = size_t(nflat) + 2;
    std::vector<float> flats(kDenseGroup * ld), hidden(size_t(kDenseGroup) * hidden_);
    for (int i = 0; i < n; ++i) {
        const float *z = crops + size_t(i) * h_ * w_;
        for (int y = 0; y < h_; ++y) std::copy(z + size_t(y) * w_, z + size_t(y + 1) * w_, &maps[0][size_t(y + 1) * (w_ + 2) + 1]);
        for (int k = 0; k < 3; ++k) {
            const Conv &c = conv_[k];
            const int W = ws[k], inw = W + 2, ow = ws[k + 1] + 2;
            float *ra = rows.data(), *rb = rows.data() + rowbuf;
            if (avx2 && !c.wino.empty() && ws[k + 1] % 6 == 0) {  // a tile row of 2 output rows = one pooled row
                for (int py = 0; py < hs[k + 1]; ++py)
                    winograd_row_pool(maps[k].data() + size_t(2 * py) * inw * c.cin, inw, ws[k + 1], c.cin, c.wino.data(),
                                      c.b.data(), c.cout, V.data(), M.data(),
                                      maps[k + 1].data() + (size_t(py + 1) * ow + 1) * c.cout);
                continue;
            }
            for (int py = 0; py < hs[k + 1]; ++py) {
                const float *in = maps[k].data() + size_t(2 * py) * inw * c.cin;
                if (avx2) {
                    conv_row_avx2(in, inw, W, c.cin, c.w.data(), c.cout, ra);
                    conv_row_avx2(in + size_t(inw) * c.cin, inw, W, c.cin, c.w.data(), c.cout, rb);
                } else {
                    conv_row_plain(in, inw, W, c.cin, c.w.data(), c.cout, ra);
                    conv_row_plain(in + size_t(inw) * c.cin, inw, W, c.cin, c.w.data(), c.cout, rb);
                }
                float *o = maps[k + 1].data() + (size_t(py + 1) * ow + 1) * c.cout;
                for (int px = 0; px < ws[k + 1]; ++px) {
                    const float *a0 = ra + size_t(2 * px) * c.cout, *a1 = a0 + c.cout;
                    const float *b0 = rb + size_t(2 * px) * c.cout, *b1 = b0 + c.cout;
                    float *op = o + size_t(px) * c.cout;
                    for (int ch = 0; ch < c.cout; ++ch)
                        op[ch] = std::max(std::max(std::max(a0[ch], a1[ch]), std::max(b0[ch], b1[ch])) + c.b[size_t(ch)], 0.f);
                }
            }
        }
        const int c3 = conv_[2].cout, ow = ws[3] + 2;
        float *flat = &flats[size_t(i % kDenseGroup) * ld];
        for (int y = 0; y < hs[3]; ++y)
            std::copy(&maps[3][(size_t(y + 1) * ow + 1) * c3], &maps[3][(size_t(y + 1) * ow + 1 + ws[3]) * c3],
                      &flat[size_t(y) * ws[3] * c3]);
        flat[size_t(nflat)] = extra[2 * i];
        flat[size_t(nflat) + 1] = extra[2 * i + 1];
        if (i % kDenseGroup != kDenseGroup - 1 && i != n - 1) continue;
        // the group's crops through the dense layer together, then each one's outputs
        const int i0 = i - i % kDenseGroup, m = i - i0 + 1;
        dense_group(flats.data(), ld, m, nflat + 2, dense_w_.data(), dense_b_.data(), hidden_, hidden.data(), avx2);
        for (int c = 0; c < m; ++c) {
            const float *h = &hidden[size_t(c) * hidden_];
            float logit = out_b_;
            for (int j = 0; j < hidden_; ++j) logit += out_w_[size_t(j)] * h[j];
            p[i0 + c] = 1.f / (1.f + std::exp(-logit));
            if (box && has_box()) {
                for (int k = 0; k < 4; ++k) {
                    float d = box_b_[size_t(k)];
                    for (int j = 0; j < hidden_; ++j) d += box_w_[size_t(k) * hidden_ + j] * h[j];
                    box[4 * (i0 + c) + k] = d;
                }
            }
        }
    }
}

} // namespace hw
