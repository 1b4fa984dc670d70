#include "detect/vehicle_verifier_cnn.hpp"

#include "base/worker_pool.hpp"
#include "detect/verifier_net.hpp"

#include <opencv2/imgproc.hpp>

#include <algorithm>
#include <cmath>
#include <stdexcept>

namespace hw {

CnnVerifier::CnnVerifier(const std::string &path, bool mirrored, double mirror_min_p, bool dnn) {
    try {
        net_ = cv::dnn::readNetFromONNX(path);
    } catch (const cv::Exception &e) {
        throw std::invalid_argument("cascade.verifier: cv::dnn cannot read '" + path + "' as ONNX (" + e.err +
                                    "); train one with `headway train verifier --out X.onnx` or set the key to off");
    }
    if (net_.empty())
        throw std::invalid_argument("cascade.verifier: '" + path + "' holds no network");
    net_.setPreferableBackend(cv::dnn::DNN_BACKEND_OPENCV);
    net_.setPreferableTarget(cv::dnn::DNN_TARGET_CPU);
    // the network's own forward pass (verifier_net.hpp), read before cv::dnn's first run fuses its layers; used once it
    // agrees with cv::dnn (below)
    std::unique_ptr<VerifierNet> own = dnn ? nullptr : VerifierNet::from_dnn(net_, kCropH, kCropW);
    // outputs: "p" alone (a network without a box output) or "p", "box" and "margin"; anything else is not a verifier network
    std::vector<cv::String> names = net_.getUnconnectedOutLayersNames();
    std::sort(names.begin(), names.end());
    const std::string form = "inputs crop (N, 1, " + std::to_string(kCropH) + ", " + std::to_string(kCropW) +
                             ") and extra (N, 2), outputs p (N, 1), optionally with box (N, 4) and margin (N, 1)";
    has_box_ = names == std::vector<cv::String>{"box", "margin", "p"};
    if (!has_box_ && names != std::vector<cv::String>{"p"}) {
        std::string got;
        for (const auto &n : names) got += (got.empty() ? "" : ", ") + n;
        throw std::invalid_argument("cascade.verifier: '" + path + "' is not a verifier network (" + form +
                                    "; it has the outputs " + got + "); train one with `headway train verifier --out X.onnx`");
    }
    outs_ = has_box_ ? std::vector<cv::String>{"p", "box"} : std::vector<cv::String>{"p"};
    // one probe: the file must take a crop and the two extra features and give one probability (and 4 offsets,
    // and its crop margin)
    try {
        const cv::Mat probe(kCropH * 4, kCropW * 4, CV_8UC1, cv::Scalar(128));
        if (has_box_) {
            net_.setInput(cv::Mat(std::vector<int>{1, 1, kCropH, kCropW}, CV_32F, cv::Scalar(0)), "crop");
            net_.setInput(cv::Mat(1, 2, CV_32F, cv::Scalar(1)), "extra");
            const cv::Mat m = net_.forward("margin");
            if (m.total() != 1 || !(m.at<float>(0) >= 0.f && m.at<float>(0) <= 1.f))
                throw std::runtime_error("output margin is not one value in 0..1");
            margin_ = m.at<float>(0);
        }
        cv::Mat offsets;
        const auto p = run(probe, {cv::Rect2f(10.f, 10.f, 60.f, 40.f)}, {3}, 0.0, 1.5, &offsets, nullptr);
        if (p.size() != 1 || !(p[0] >= 0.f && p[0] <= 1.f)) throw std::runtime_error("no probability");
    } catch (const std::exception &e) {
        throw std::invalid_argument("cascade.verifier: '" + path + "' is not a verifier network (" + form + "): " +
                                    e.what() + "; train one with `headway train verifier --out X.onnx`");
    }
    own_ = std::move(own);
    if (own_) {
        const double diff = own_disagreement();
        if (!(diff <= 1e-4))  // a graph of the form whose weights it misreads: a bug here, never a wrong answer
            throw std::invalid_argument("cascade.verifier: the own forward pass of '" + path + "' differs from cv::dnn's by " +
                                        std::to_string(diff) + "; set cascade.verifier_dnn: true and report it");
    }
    mirrored_ = mirrored;  // after the probe, which checks the file's own answer
    mirror_min_p_ = mirror_min_p;
}

namespace {

// The mean of every cell of a kCropW x kCropH grid laid over the source rectangle [x0, x1) x [y0, y1) (whole pixels,
// inside the image, at least the crop's size), rounded: the pixel-area average cv::resize(INTER_AREA) computes, from
// the image's integral ii (CV_32S, (rows + 1) x (cols + 1)). The integral of a piecewise-constant image is bilinear
// between whole pixels, so each cell corner's integral is an exact bilinear read of ii: the cost is per cell, not per
// source pixel (the groups of a frame overlap: their crops span ~2.4 M source pixels of a 0.9 M pixel image).
// OpenCV's own arithmetic (float weights, partial pixels under 1e-3 dropped) differs by one grey level on ~0.1 % of
// the pixels (docs/detection.md).
template <int W, int H>
void area_cells(const cv::Mat &ii, int x0, int y0, int x1, int y1, cv::Mat &out) {
    const double sx = double(x1 - x0) / W, sy = double(y1 - y0) / H;
    int xi[W + 1], yi[H + 1];
    double xf[W + 1], yf[H + 1];
    for (int c = 0; c <= W; ++c) {
        const double x = c == W ? double(x1) : x0 + c * sx;
        xi[c] = std::min(int(std::floor(x)), ii.cols - 2);  // x == cols: the last cell, fraction 1
        xf[c] = x - xi[c];
    }
    for (int r = 0; r <= H; ++r) {
        const double y = r == H ? double(y1) : y0 + r * sy;
        yi[r] = std::min(int(std::floor(y)), ii.rows - 2);
        yf[r] = y - yi[r];
    }
    double prev[W + 1], cur[W + 1];
    const double inv_area = 1.0 / (sx * sy);
    for (int r = 0; r <= H; ++r) {
        const int *a = ii.ptr<int>(yi[r]), *b = ii.ptr<int>(yi[r] + 1);
        const double fy = yf[r];
        for (int c = 0; c <= W; ++c) {
            const int i = xi[c];
            const double top = a[i] + xf[c] * (a[i + 1] - a[i]);
            const double bottom = b[i] + xf[c] * (b[i + 1] - b[i]);
            cur[c] = top + fy * (bottom - top);
        }
        if (r > 0) {
            uchar *o = out.ptr<uchar>(r - 1);
            for (int c = 0; c < W; ++c)
                o[c] = cv::saturate_cast<uchar>((cur[c + 1] - cur[c] - prev[c + 1] + prev[c]) * inv_area);
        }
        std::copy(cur, cur + W + 1, prev);
    }
}

} // namespace

cv::Mat CnnVerifier::crop(const cv::Mat &gray, const cv::Rect2f &box, double margin, const cv::Mat *integral) {
    // the box's edges as the Python side sees them (float right = x + width), widened in double
    const double l = box.x, t = box.y, r = double(box.x + box.width), b = double(box.y + box.height);
    const double mx = margin * (r - l), my = margin * (b - t);
    const int x0 = int(std::floor(l - mx + 0.5)), y0 = int(std::floor(t - my + 0.5));
    const int x1 = int(std::floor(r + mx + 0.5)), y1 = int(std::floor(b + my + 0.5));
    cv::Mat out(kCropH, kCropW, CV_32F, cv::Scalar(0));
    if (x1 - x0 < 2 || y1 - y0 < 2) return out;
    cv::Mat small(kCropH, kCropW, CV_8U);
    if (integral && x0 >= 0 && y0 >= 0 && x1 <= gray.cols && y1 <= gray.rows && x1 - x0 >= kCropW && y1 - y0 >= kCropH) {
        area_cells<kCropW, kCropH>(*integral, x0, y0, x1, y1, small);
    } else {  // reaching out of the image (border replicated), or smaller than the crop (INTER_AREA interpolates)
        const int cx0 = std::clamp(x0, 0, gray.cols - 1), cy0 = std::clamp(y0, 0, gray.rows - 1);
        const int cx1 = std::max(std::min(x1, gray.cols), cx0 + 1), cy1 = std::max(std::min(y1, gray.rows), cy0 + 1);
        cv::Mat padded;
        cv::copyMakeBorder(gray(cv::Rect(cx0, cy0, cx1 - cx0, cy1 - cy0)), padded, cy0 - y0, std::max(0, y1 - cy1),
                           cx0 - x0, std::max(0, x1 - cx1), cv::BORDER_REPLICATE);
        cv::resize(padded, small, cv::Size(kCropW, kCropH), 0, 0, cv::INTER_AREA);
    }
    cv::Scalar mean, sd;
    cv::meanStdDev(small, mean, sd);
    small.convertTo(out, CV_32F, 1.0 / (sd[0] + 1.0), -mean[0] / (sd[0] + 1.0));
    return out;
}

void CnnVerifier::batch(const cv::Mat &gray, const std::vector<cv::Rect2f> &boxes, const std::vector<int> &neighbors,
                        const std::vector<int> &which, const cv::Mat *plain, const cv::Mat *integral,
                        double horizon_row, double cam_height_m, float *p, cv::Mat *offsets, cv::Mat *crops_out) const {
    const int n = int(which.size());
    const int sz[4] = {n, 1, kCropH, kCropW};
    cv::Mat crops(4, sz, CV_32F), extra(n, 2, CV_32F), made;
    if (!plain && !integral) {  // once for all the crops of the batch (area_cells)
        made = integral_of(gray);
        integral = &made;
    }
    const auto cut = [&](int k0, int k1) {  // each crop on its own: the same values on any thread
        for (int k = k0; k < k1; ++k) {
            const size_t i = size_t(which[size_t(k)]);
            cv::Mat c(kCropH, kCropW, CV_32F, crops.ptr<float>(k));
            if (plain)  // the crop is centred on the box, so its mirror image is the mirrored image's crop
                cv::flip(cv::Mat(kCropH, kCropW, CV_32F, const_cast<float *>(plain->ptr<float>(int(i)))), c, 1);
            else
                crop(gray, boxes[i], margin_, integral).copyTo(c);
            extra.at<float>(k, 0) = float(std::log1p(double(neighbors[i])));
            extra.at<float>(k, 1) = implied_vehicle_height(boxes[i], horizon_row, cam_height_m);
        }
    };
    // pieces of kPiece crops taken one at a time, as VerifierNet::forward shares the network's work: a worker that
    // wakes late leaves the caller nothing to wait for (base/worker_pool.hpp)
    constexpr int kPiece = 8;
    const int pieces = (n + kPiece - 1) / kPiece;
    if (pool_ && pool_->threads() > 1 && pieces > 1)
        pool_->run(pieces, [&](int j, int) { cut(j * kPiece, std::min(n, (j + 1) * kPiece)); });
    else
        cut(0, n);
    if (has_box_ && offsets) offsets->create(n, 4, CV_32F);
    forward(crops, extra, p, offsets);
    if (crops_out) *crops_out = crops;
}

void CnnVerifier::forward(const cv::Mat &crops, const cv::Mat &extra, float *p, cv::Mat *offsets, bool dnn) const {
    const int n = crops.size[0];
    if (own_ && !dnn) {  // verifier_net.hpp: the same network, several times faster than cv::dnn on these small layers
        own_->forward(crops.ptr<float>(), extra.ptr<float>(), n, p, has_box_ && offsets ? offsets->ptr<float>() : nullptr);
        return;
    }
    // kChunk boxes at a time: a frame's ~100 crops at once spill the layers' outputs out of the cache (measured 7.0
    // against 8.1 ms for ~112 crops, docs/decisions.md); each box's answer is its own either way
    for (int k0 = 0; k0 < n; k0 += kChunk) {
        const int m = std::min(kChunk, n - k0);
        const int szm[4] = {m, 1, kCropH, kCropW};
        net_.setInput(cv::Mat(4, szm, CV_32F, const_cast<float *>(crops.ptr<float>(k0))), "crop");
        net_.setInput(extra.rowRange(k0, k0 + m), "extra");
        std::vector<cv::Mat> out;
        net_.forward(out, outs_);
        if (out[0].total() != size_t(m))
            throw std::runtime_error("output p holds " + std::to_string(out[0].total()) + " values for " +
                                     std::to_string(m) + " boxes");
        std::copy(out[0].ptr<float>(), out[0].ptr<float>() + m, p + k0);
        if (has_box_) {
            if (out[1].total() != size_t(4 * m))
                throw std::runtime_error("output box holds " + std::to_string(out[1].total()) + " values for " +
                                         std::to_string(m) + " boxes, not 4 each");
            if (offsets) out[1].reshape(1, m).copyTo(offsets->rowRange(k0, k0 + m));
        }
    }
}

void CnnVerifier::set_pool(WorkerPool *pool) {
    pool_ = pool;
    if (own_) own_->set_pool(pool);  // cv::dnn keeps its own threading
}

double CnnVerifier::own_disagreement() const {
    // crops of standard normal values (what standardised crops look like) and plausible extra features
    const int n = 2 * kChunk + 3, sz[4] = {n, 1, kCropH, kCropW};
    cv::Mat crops(4, sz, CV_32F), extra(n, 2, CV_32F);
    cv::RNG rng(20261201);
    rng.fill(crops, cv::RNG::NORMAL, 0.0, 1.0);
    for (int k = 0; k < n; ++k) {
        extra.at<float>(k, 0) = float(std::log1p(double(1 + k)));
        extra.at<float>(k, 1) = 0.5f + 0.1f * float(k);
    }
    cv::Mat pd(n, 1, CV_32F), dd(n, 4, CV_32F, cv::Scalar(0));
    forward(crops, extra, pd.ptr<float>(), &dd, true);
    double worst = 0.0;
    for (const bool plain : {false, true}) {
        // the plain loops (the path of CPUs without AVX2, ~10x slower here) on the first few crops only: a misread
        // weight shows on any crop, and every crop more costs ~1 ms when a file is loaded
        const int m = plain ? 4 : n;
        cv::Mat po(m, 1, CV_32F), dn(m, 4, CV_32F, cv::Scalar(0));
        if (plain) own_->forward_plain(crops.ptr<float>(), extra.ptr<float>(), m, po.ptr<float>(), dn.ptr<float>());
        else own_->forward(crops.ptr<float>(), extra.ptr<float>(), m, po.ptr<float>(), dn.ptr<float>());
        worst = std::max({worst, cv::norm(pd.rowRange(0, m), po, cv::NORM_INF),
                          has_box_ ? cv::norm(dd.rowRange(0, m), dn, cv::NORM_INF) : 0.0});
    }
    return worst;
}

std::vector<float> CnnVerifier::run(const cv::Mat &gray, const std::vector<cv::Rect2f> &boxes,
                                     const std::vector<int> &neighbors, double horizon_row, double cam_height_m,
                                     cv::Mat *offsets, const cv::Mat *integral) const {
    const int n = int(boxes.size());
    if (n == 0) return {};
    std::vector<int> all(static_cast<size_t>(n));
    for (int i = 0; i < n; ++i) all[size_t(i)] = i;
    std::vector<float> p(static_cast<size_t>(n));
    cv::Mat d, crops;
    batch(gray, boxes, neighbors, all, nullptr, integral, horizon_row, cam_height_m, p.data(), &d,
          mirrored_ ? &crops : nullptr);
    if (mirrored_) {  // the mirror images of the boxes the plain look gives at least mirror_min_p
        std::vector<int> which;
        for (int i = 0; i < n; ++i)
            if (p[size_t(i)] >= mirror_min_p_) which.push_back(i);
        if (!which.empty()) {
            std::vector<float> pm(which.size());
            cv::Mat dm;
            // the plain crops flipped (not cut again: the same values, half the cropping)
            batch(gray, boxes, neighbors, which, &crops, nullptr, horizon_row, cam_height_m, pm.data(), &dm, nullptr);
            for (size_t k = 0; k < which.size(); ++k) {
                const int i = which[k];
                p[size_t(i)] = 0.5f * (p[size_t(i)] + pm[k]);
                if (!has_box_) continue;
                // the mirror's left edge is the box's right one, and its offsets point the other way
                float *o = d.ptr<float>(i);
                const float *m = dm.ptr<float>(int(k));
                const float l = 0.5f * (o[0] - m[2]), t = 0.5f * (o[1] + m[1]);
                const float r = 0.5f * (o[2] - m[0]), b = 0.5f * (o[3] + m[3]);
                o[0] = l; o[1] = t; o[2] = r; o[3] = b;
            }
        }
    }
    if (has_box_ && offsets) *offsets = d;
    return p;
}

cv::Mat CnnVerifier::integral_of(const cv::Mat &gray) const {
    cv::Mat ii;
    cv::integral(gray, ii, CV_32S);
    return ii;
}

std::vector<float> CnnVerifier::probabilities(const cv::Mat &gray, const std::vector<cv::Rect2f> &boxes,
                                              const std::vector<int> &neighbors, double horizon_row,
                                              double cam_height_m, const cv::Mat *integral) const {
    return run(gray, boxes, neighbors, horizon_row, cam_height_m, nullptr, integral);
}

std::vector<float> CnnVerifier::judge(const cv::Mat &gray, std::vector<cv::Rect2f> &boxes,
                                      const std::vector<int> &neighbors, double horizon_row, double cam_height_m,
                                      const cv::Mat *integral) const {
    cv::Mat d;
    std::vector<float> p = run(gray, boxes, neighbors, horizon_row, cam_height_m, &d, integral);
    for (int i = 0; i < d.rows; ++i) {  // l' = l + d0 w, t' = t + d1 h, r' = r + d2 w, b' = b + d3 h
        cv::Rect2f &b = boxes[size_t(i)];
        const float *o = d.ptr<float>(i);
        const double w = b.width, h = b.height;
        const double l = b.x + o[0] * w, t = b.y + o[1] * h;
        const double r = double(b.x + b.width) + o[2] * w, bt = double(b.y + b.height) + o[3] * h;
        if (r - l < 1.0 || bt - t < 1.0) continue;  // a degenerate box: keep the group's own
        b = cv::Rect2f(float(l), float(t), float(r - l), float(bt - t));
    }
    return p;
}

} // namespace hw
