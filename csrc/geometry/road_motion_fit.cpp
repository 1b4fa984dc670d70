#include "geometry/road_motion_fit.hpp"

#include <opencv2/calib3d.hpp>

#include <algorithm>
#include <cmath>

namespace hw {

cv::Matx33d mounting_rotation(const CameraParams &cam) {
    const double p = cam.pitch_deg * M_PI / 180.0, b = cam.yaw_deg * M_PI / 180.0;
    // The mounting as in travel_homography(): yaw about y, then pitch about x.
    const cv::Matx33d Ryaw(std::cos(b), 0, -std::sin(b), 0, 1, 0, std::sin(b), 0, std::cos(b));
    const cv::Matx33d Rpitch(1, 0, 0, 0, std::cos(p), -std::sin(p), 0, std::sin(p), std::cos(p));
    return Rpitch * Ryaw;
}

namespace {

// M = R_c^T K^-1 H K R_c = s R' (I - t n^T / h): (s, R', M's middle column); s = 0 when H is degenerate.
struct LevelMotion {
    double s = 0.0;
    cv::Matx33d R = cv::Matx33d::eye();
    cv::Vec3d m1;
};

LevelMotion level_motion(const cv::Matx33d &H, const CameraParams &cam) {
    const cv::Matx33d Rc = mounting_rotation(cam);
    const cv::Matx33d K(cam.fx, 0, cam.cx, 0, cam.fy, cam.cy, 0, 0, 1);
    const cv::Matx33d M = Rc.t() * K.inv() * H * K * Rc;
    const cv::Vec3d m0(M(0, 0), M(1, 0), M(2, 0)), m2(M(0, 2), M(1, 2), M(2, 2));
    LevelMotion out;
    out.m1 = cv::Vec3d(M(0, 1), M(1, 1), M(2, 1));
    const double s = cv::norm(m0);
    if (!(s > 1e-12)) return out;
    const cv::Vec3d r0 = m0 / s, r2 = m2 / s, r1 = r2.cross(r0);
    out.s = s;
    out.R = cv::Matx33d(r0[0], r1[0], r2[0], r0[1], r1[1], r2[1], r0[2], r1[2], r2[2]);
    return out;
}

} // namespace

cv::Vec3d road_motion_translation(const cv::Matx33d &H, const CameraParams &cam) {
    const LevelMotion m = level_motion(H, cam);
    if (m.s == 0.0) return {NAN, NAN, NAN};
    return (cv::Vec3d(0, 1, 0) - m.R.t() * (m.m1 / m.s)) * cam.height_m;
}

cv::Matx33d road_motion_rotation(const cv::Matx33d &H, const CameraParams &cam) { return level_motion(H, cam).R; }

cv::Matx33d road_motion_homography(const CameraParams &cam, const cv::Vec<double, 5> &theta, double tilt_rad) {
    const cv::Matx33d Rc = mounting_rotation(cam);
    cv::Matx33d Rd;
    cv::Rodrigues(cv::Vec3d(theta[0], theta[1], theta[2]), Rd);
    const double h = cam.height_m;
    // I - t n^T / h, t = (lateral, 0, travel), n = (0, cos e, sin e): the middle and last columns change
    // (only the middle one on the assumed plane, e = 0).
    const double c = std::cos(tilt_rad) / h, s = std::sin(tilt_rad) / h;
    const cv::Matx33d T(1, -theta[3] * c, -theta[3] * s, 0, 1, 0, 0, -theta[4] * c, 1 - theta[4] * s);
    const cv::Matx33d K(cam.fx, 0, cam.cx, 0, cam.fy, cam.cy, 0, 0, 1);
    cv::Matx33d G = K * Rd * Rc * T * Rc.t() * K.inv();
    return G * (1.0 / G(2, 2));
}

namespace {

// The model's homography of N parameters: the five of road_motion_homography, and the tilt as a sixth.
template <int N>
cv::Matx33d model_homography(const CameraParams &cam, const cv::Vec<double, N> &th) {
    return road_motion_homography(cam, cv::Vec<double, 5>(th[0], th[1], th[2], th[3], th[4]), N > 5 ? th[N - 1] : 0.0);
}

// Transfer residuals (dx, dy per point) of the model at theta.
template <int N>
void residuals(const CameraParams &cam, const cv::Vec<double, N> &theta, const std::vector<cv::Point2f> &from,
               const std::vector<cv::Point2f> &to, std::vector<double> &r) {
    const cv::Matx33d H = model_homography<N>(cam, theta);
    r.resize(2 * from.size());
    for (size_t i = 0; i < from.size(); ++i) {
        const cv::Vec3d q = H * cv::Vec3d(from[i].x, from[i].y, 1.0);
        r[2 * i] = q[0] / q[2] - to[i].x;
        r[2 * i + 1] = q[1] / q[2] - to[i].y;
    }
}

// Gauss-Newton from th (the model is nearly linear in every parameter: small angles, and the translation
// enters linearly before the projection), Jacobian by forward differences (steps far below the
// parameters' precision, far above the rounding of the residuals); at most 8 iterations. False when the
// normal equations are singular (the tilt at rest: it acts only through the travel).
template <int N>
bool gauss_newton(const CameraParams &cam, const std::vector<cv::Point2f> &f, const std::vector<cv::Point2f> &t,
                  cv::Vec<double, N> &th) {
    const double step[6] = {1e-6, 1e-6, 1e-6, 1e-4, 1e-4, 1e-6};
    std::vector<double> r, rp;
    std::vector<cv::Vec<double, N>> J;
    for (int it = 0; it < 8; ++it) {
        residuals<N>(cam, th, f, t, r);
        cv::Matx<double, N, N> JtJ = cv::Matx<double, N, N>::zeros();
        cv::Vec<double, N> Jtr = cv::Vec<double, N>::all(0.0);
        J.resize(r.size());
        for (int k = 0; k < N; ++k) {
            cv::Vec<double, N> a = th;
            a[k] += step[k];
            residuals<N>(cam, a, f, t, rp);
            for (size_t i = 0; i < r.size(); ++i) J[i][k] = (rp[i] - r[i]) / step[k];
        }
        for (size_t i = 0; i < r.size(); ++i) {
            for (int a = 0; a < N; ++a) {
                Jtr[a] += J[i][a] * r[i];
                for (int b = 0; b < N; ++b) JtJ(a, b) += J[i][a] * J[i][b];
            }
        }
        cv::Vec<double, N> d;
        if (!cv::solve(JtJ, -Jtr, d, cv::DECOMP_CHOLESKY)) return false;
        th += d;
        // converged: the update moves no road point by more than ~0.01 px
        double angles = std::abs(d[0]) + std::abs(d[1]) + std::abs(d[2]) + (N > 5 ? std::abs(d[N - 1]) : 0.0);
        if (angles < 1e-6 && std::abs(d[3]) + std::abs(d[4]) < 1e-4) break;
    }
    return true;
}

} // namespace

RoadMotionFit fit_road_motion(const std::vector<cv::Point2f> &from, const std::vector<cv::Point2f> &to,
                              const cv::Matx33d &dlt, const CameraParams &cam, const DltParams &p, bool free_tilt) {
    RoadMotionFit out;
    // The correspondences the DLT explains (its trimming rule): a wrong one has the same leverage here.
    std::vector<double> e(from.size());
    for (size_t i = 0; i < from.size(); ++i) e[i] = transfer_error(dlt, from[i], to[i]);
    std::vector<double> sorted = e;
    if (sorted.size() < 5) return out;
    std::nth_element(sorted.begin(), sorted.begin() + long(sorted.size() / 2), sorted.end());
    const double lim = std::max(p.trim_floor_px, (p.trim_factor > 0 ? p.trim_factor : 1e9) * sorted[sorted.size() / 2]);
    std::vector<cv::Point2f> f, t;
    for (size_t i = 0; i < from.size(); ++i)
        if (e[i] <= lim) { f.push_back(from[i]); t.push_back(to[i]); }
    if (int(f.size()) < std::max(5, p.min_points)) return out;

    // from rest; the tilt then from the five-parameter solution (at rest it has no effect: singular)
    const auto rms = [&](const std::vector<double> &res) {
        double ss = 0;
        for (double v : res) ss += v * v;
        return std::sqrt(ss / double(f.size()));
    };
    std::vector<double> r;
    cv::Vec<double, 5> th5 = cv::Vec<double, 5>::all(0.0);
    if (!gauss_newton<5>(cam, f, t, th5)) return out;
    residuals<5>(cam, th5, f, t, r);
    out.rms_px = rms(r);
    out.theta = th5;
    out.H = road_motion_homography(cam, th5);
    out.used = int(f.size());
    out.ok = std::isfinite(out.rms_px) && out.rms_px <= p.max_rms_px;
    if (free_tilt && f.size() >= 6) {
        cv::Vec<double, 6> th(th5[0], th5[1], th5[2], th5[3], th5[4], 0.0);
        if (gauss_newton<6>(cam, f, t, th)) {
            residuals<6>(cam, th, f, t, r);
            const double e = rms(r);
            out.tilt_ok = std::isfinite(e) && e <= p.max_rms_px;
            out.tilt_rad = th[5];
            out.tilt_travel_m = th[4];
        }
    }
    return out;
}

} // namespace hw
