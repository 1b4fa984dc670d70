#include "geometry/homography_dlt.hpp"

#include <Eigen/Dense>
#include <opencv2/calib3d.hpp>

#include <algorithm>
#include <cmath>
#include <stdexcept>

namespace hw {

void DltParams::bind(ParamMap &m) {
    m.add("min_points", min_points, 4, 10000,
          "count; correspondences needed for a homography measurement; 8 leaves the DLT over-determined "
          "twice over, so one bad point shows in the residual");
    m.add("point_gate_px", point_gate_px, 0.0, 10000.0,
          "px; a correspondence farther than this from where the predicted homography puts it is dropped before "
          "the DLT (a wrong dash, a vehicle's corner); 0 disables");
    m.add("min_row_span_px", min_row_span_px, 0.0, 10000.0,
          "px; the used points must spread over this many rows; points in a thin band near the horizon fix the "
          "homography poorly (the paper's warning)");
    m.add("trim_factor", trim_factor, 0.0, 100.0,
          "medians; correspondences whose transfer error exceeds this many median errors are dropped and the DLT "
          "refit once; 0 keeps the plain DLT of the paper");
    m.add("trim_floor_px", trim_floor_px, 0.0, 100.0,
          "px; a correspondence is never trimmed for an error below this (LK is good to a fraction of a pixel)");
    m.add("ransac_px", ransac_px, 0.1, 100.0,
          "px; without a prediction the correspondences are first filtered by a RANSAC homography with this inlier "
          "distance (LK is good to a fraction of a pixel; a wrong dash is tens of pixels off)");
    m.add("max_rms_px", max_rms_px, 0.01, 100.0,
          "px; a fit whose rms transfer error is larger is not a plane (points on vehicles, slid along markings) "
          "and gives no measurement");
}

namespace {

// Similarity T with T x = s (x - c): centroid to the origin, mean distance sqrt(2).
cv::Matx33d normaliser(const std::vector<cv::Point2f> &pts) {
    double cx = 0, cy = 0;
    for (const auto &p : pts) { cx += p.x; cy += p.y; }
    cx /= double(pts.size());
    cy /= double(pts.size());
    double d = 0;
    for (const auto &p : pts) d += std::hypot(p.x - cx, p.y - cy);
    d /= double(pts.size());
    const double s = d > 1e-12 ? std::sqrt(2.0) / d : 1.0;
    return {s, 0, -s * cx, 0, s, -s * cy, 0, 0, 1};
}

cv::Point2d apply(const cv::Matx33d &T, cv::Point2f p) {
    const cv::Vec3d q = T * cv::Vec3d(p.x, p.y, 1.0);
    return {q[0] / q[2], q[1] / q[2]};
}

} // namespace

cv::Matx33d normalised_dlt(const std::vector<cv::Point2f> &from, const std::vector<cv::Point2f> &to) {
    if (from.size() != to.size() || from.size() < 4)
        throw std::invalid_argument("normalised_dlt: needs >= 4 correspondences of equal count");
    const cv::Matx33d T = normaliser(from), Tp = normaliser(to);
    // Accumulate A^T A (9x9) directly: two rows per correspondence.
    Eigen::Matrix<double, 9, 9> AtA = Eigen::Matrix<double, 9, 9>::Zero();
    for (size_t i = 0; i < from.size(); ++i) {
        const cv::Point2d x = apply(T, from[i]), xp = apply(Tp, to[i]);
        Eigen::Matrix<double, 9, 1> r1, r2;
        r1 << 0, 0, 0, -x.x, -x.y, -1, xp.y * x.x, xp.y * x.y, xp.y;
        r2 << x.x, x.y, 1, 0, 0, 0, -xp.x * x.x, -xp.x * x.y, -xp.x;
        AtA.noalias() += r1 * r1.transpose() + r2 * r2.transpose();
    }
    Eigen::SelfAdjointEigenSolver<Eigen::Matrix<double, 9, 9>> es(AtA);
    const Eigen::Matrix<double, 9, 1> h = es.eigenvectors().col(0);  // smallest eigenvalue first
    const cv::Matx33d Hn(h(0), h(1), h(2), h(3), h(4), h(5), h(6), h(7), h(8));
    cv::Matx33d H = Tp.inv() * Hn * T;
    if (std::fabs(H(2, 2)) < 1e-12) throw std::invalid_argument("normalised_dlt: degenerate configuration");
    return H * (1.0 / H(2, 2));
}

double transfer_error(const cv::Matx33d &H, cv::Point2f from, cv::Point2f to) {
    const cv::Point2d q = apply(H, from);
    return std::hypot(q.x - to.x, q.y - to.y);
}

HomographyFit fit_homography(const std::vector<cv::Point2f> &from, const std::vector<cv::Point2f> &to,
                             const DltParams &p, const cv::Matx33d *predicted) {
    CV_Assert(from.size() == to.size());
    HomographyFit fit;
    auto row_span = [](const std::vector<cv::Point2f> &pts) {
        float lo = 1e9f, hi = -1e9f;
        for (const auto &q : pts) { lo = std::min(lo, q.y); hi = std::max(hi, q.y); }
        return pts.empty() ? 0.f : hi - lo;
    };
    std::vector<cv::Point2f> f, t;
    std::vector<uint8_t> inlier(from.size(), 1);
    if (!predicted && int(from.size()) >= std::max(4, p.min_points))
        cv::findHomography(from, to, cv::RANSAC, p.ransac_px, inlier, 500, 0.999);
    for (size_t i = 0; i < from.size(); ++i)
        if (inlier[i] && (!predicted || p.point_gate_px <= 0 || transfer_error(*predicted, from[i], to[i]) <= p.point_gate_px)) {
            f.push_back(from[i]);
            t.push_back(to[i]);
        }
    if (int(f.size()) < std::max(4, p.min_points) || row_span(t) < p.min_row_span_px) return fit;

    cv::Matx33d H = normalised_dlt(f, t);
    std::vector<double> err(f.size());
    for (size_t i = 0; i < f.size(); ++i) err[i] = transfer_error(H, f[i], t[i]);
    if (p.trim_factor > 0) {
        std::vector<double> sorted = err;
        std::nth_element(sorted.begin(), sorted.begin() + sorted.size() / 2, sorted.end());
        const double limit = std::max(p.trim_floor_px, p.trim_factor * sorted[sorted.size() / 2]);
        std::vector<cv::Point2f> f2, t2;
        for (size_t i = 0; i < f.size(); ++i)
            if (err[i] <= limit) { f2.push_back(f[i]); t2.push_back(t[i]); }
        if (f2.size() < f.size()) {
            if (int(f2.size()) < std::max(4, p.min_points) || row_span(t2) < p.min_row_span_px) return fit;
            f.swap(f2);
            t.swap(t2);
            H = normalised_dlt(f, t);
            err.resize(f.size());
            for (size_t i = 0; i < f.size(); ++i) err[i] = transfer_error(H, f[i], t[i]);
        }
    }
    double ss = 0;
    for (double e : err) ss += e * e;
    fit.rms_px = std::sqrt(ss / double(err.size()));
    fit.used = int(f.size());
    fit.H = H;
    fit.ok = fit.rms_px <= p.max_rms_px && std::isfinite(fit.rms_px);
    return fit;
}

} // namespace hw
