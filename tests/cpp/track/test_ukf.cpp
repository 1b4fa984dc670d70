// The unscented Kalman filter (paper 004, eq. 16-21): on a linear observation it is the Kalman filter; on the
// pinhole observation of a vehicle's contact point its range rate is several times better than the plain
// flat-road inversion and as good as inverting each row and Kalman-filtering the range (what the box trackers'
// range filter does); the image-expansion observation halves the rate bias of a contact row one pixel low.
#include "geometry/flat_road.hpp"
#include "track/phd/ukf.hpp"

#include <doctest/doctest.h>

#include <cmath>
#include <random>
#include <vector>

using hw::Ukf;
using Mat = Eigen::MatrixXd;
using Vec = Eigen::VectorXd;

namespace {

constexpr double kDt = 1.0 / 30;

hw::CameraParams camera() { return {}; }  // fx = fy 700, (320, 240), 1.3 m high, pitched 1 deg down

// eq. 19: constant velocity on the state [X, Z, dX/dt, dZ/dt]
Vec constant_velocity(const Vec &x, double dt) {
    Vec y = x;
    y(0) += dt * x(2);
    y(1) += dt * x(3);
    return y;
}

Mat transition() {
    Mat F = Mat::Identity(4, 4);
    F(0, 2) = F(1, 3) = kDt;
    return F;
}

// White acceleration per axis: sigma^2 [dt^3/3 dt^2/2; dt^2/2 dt].
Mat white_accel(double sx, double sz) {
    Mat Q = Mat::Zero(4, 4);
    const double a = kDt * kDt * kDt / 3, b = kDt * kDt / 2;
    for (auto [i, s2] : {std::pair<int, double>{0, sx * sx}, {1, sz * sz}}) {
        Q(i, i) = a * s2;
        Q(i, i + 2) = Q(i + 2, i) = b * s2;
        Q(i + 2, i + 2) = kDt * s2;
    }
    return Q;
}

// Runs the UKF over the observation rows of z (a NaN row: prediction only); the state after each step.
std::vector<Vec> run_ukf(const hw::UkfParams &up, const Vec &x0, const Mat &P0, const Mat &Q, const Mat &R,
                         const Ukf::Observation &h, const std::vector<Vec> &z, std::vector<Mat> *covs = nullptr) {
    Ukf f(up, x0, P0);
    std::vector<Vec> xs;
    for (size_t k = 0; k < z.size(); ++k) {
        if (k) f.predict(constant_velocity, kDt, Q);
        if (z[k].allFinite()) f.update(h, z[k], R);
        xs.push_back(f.x());
        if (covs) covs->push_back(f.P());
    }
    return xs;
}

// The contact point (u, v) of the road point (X, Z), and e = -(dZ/dt)/Z when the observation has three rows.
Ukf::Observation pinhole(int dim) {
    return [dim](const Vec &x) {
        const hw::CameraParams cam = camera();
        const cv::Point2d p = hw::project_road_point(cam, x(0), x(1), cam.horizon_row());
        Vec y(dim);
        y(0) = p.x;
        y(1) = p.y;
        if (dim == 3) y(2) = x(1) > 0.1 ? -x(3) / x(1) : NAN;
        return y;
    };
}

hw::RoadPoint invert(double u, double v) {
    const hw::CameraParams cam = camera();
    return hw::road_point(cam, u, v, cam.horizon_row());
}

struct Approach {
    std::vector<Vec> obs;  // (u, v) per frame
    std::vector<double> Z;
    double rate;
};

Approach approach(uint32_t seed, double z0, double rate, int n, double sigma) {
    std::mt19937 rng(seed);
    std::normal_distribution<double> noise(0.0, sigma);
    const hw::CameraParams cam = camera();
    Approach a{{}, {}, rate};
    for (int k = 0; k < n; ++k) {
        const double t = k * kDt, X = 0.4 + 0.1 * t, Z = z0 + rate * t;
        const cv::Point2d p = hw::project_road_point(cam, X, Z, cam.horizon_row());
        Vec o(2);
        o << p.x + noise(rng), p.y + noise(rng);
        a.obs.push_back(o);
        a.Z.push_back(Z);
    }
    return a;
}

double rmse(const std::vector<double> &e) {
    double s = 0;
    for (double x : e) s += x * x;
    return std::sqrt(s / double(e.size()));
}

// The box trackers' way: each contact row inverted to a range on the flat road, then a constant-velocity Kalman
// filter on that range with the row noise carried through dZ/dv = -Z^2/(fy h). The range rate per frame.
std::vector<double> flat_road_kf(const std::vector<Vec> &obs, double sigma, const Mat &Q, const Mat &P0) {
    const hw::CameraParams cam = camera();
    Eigen::Matrix2d Fz, Qz, P;
    Fz << 1, kDt, 0, 1;
    Qz << Q(1, 1), Q(1, 3), Q(3, 1), Q(3, 3);
    P << P0(1, 1), P0(1, 3), P0(3, 1), P0(3, 3);
    Eigen::Vector2d x(invert(obs[0](0), obs[0](1)).z_m, 0.0);
    std::vector<double> rates;
    for (size_t k = 0; k < obs.size(); ++k) {
        const double zk = invert(obs[k](0), obs[k](1)).z_m;
        if (k) {
            x = Fz * x;
            P = Fz * P * Fz.transpose() + Qz;
        }
        const double r = std::pow(x(0) * x(0) / (cam.fy * cam.height_m) * sigma, 2);
        const double S = P(0, 0) + r;
        const Eigen::Vector2d K = P.col(0) / S;
        x += K * (zk - x(0));
        P -= K * P.row(0);
        rates.push_back(x(1));
    }
    return rates;
}

} // namespace

TEST_CASE("UKF with a linear observation is the Kalman filter") {
    std::mt19937 rng(1);
    std::normal_distribution<double> n01(0.0, 1.0);
    Mat H(2, 4), R(2, 2), P0 = Vec((Vec(4) << 1.0, 25.0, 4.0, 100.0).finished()).asDiagonal();
    H << 1, 0, 0, 0, 0, 1, 0.2, 0;
    R << 0.3, 0.05, 0.05, 0.8;
    const Mat Q = white_accel(1.0, 2.0), F = transition();
    const Vec x0 = (Vec(4) << 1.0, 40.0, 0.0, -3.0).finished();
    std::vector<Vec> z;
    for (int k = 0; k < 60; ++k) {
        Vec zk(2);
        zk << 1 + k / 59.0 + n01(rng), 40 - 10 * k / 59.0 + n01(rng);
        z.push_back(zk);
    }
    z[17].setConstant(NAN);  // a frame without a measurement: prediction only
    for (auto [alpha, beta, kappa] : {std::tuple{1.0, 2.0, 0.0}, {0.5, 2.0, 1.0}, {1e-3, 2.0, 0.0}}) {
        hw::UkfParams up;
        up.alpha = alpha;
        up.beta = beta;
        up.kappa = kappa;
        std::vector<Mat> Ps;
        const auto xs = run_ukf(up, x0, P0, Q, R, [&](const Vec &x) { return Vec(H * x); }, z, &Ps);
        Vec x = x0;
        Mat P = P0;
        const double tol = 1e-9 * std::max(1.0, 1 / (alpha * alpha));
        for (size_t k = 0; k < z.size(); ++k) {
            if (k) {
                x = F * x;
                P = F * P * F.transpose() + Q;
            }
            if (z[k].allFinite()) {
                const Mat S = H * P * H.transpose() + R, K = P * H.transpose() * S.inverse();
                x += K * (z[k] - H * x);
                P -= K * S * K.transpose();
            }
            CHECK((xs[k] - x).cwiseAbs().maxCoeff() <= tol);
            CHECK((Ps[k] - P).cwiseAbs().maxCoeff() <= tol);
        }
    }
}

TEST_CASE("pinhole UKF beats the flat-road inversion in range rate") {
    const hw::CameraParams cam = camera();
    const Mat Q = white_accel(1.5, 3.0);
    // measured: UKF 1.35 / 2.61 / 1.64 m/s, flat-road + KF 1.37 / 2.73 / 1.70, plain inversion 11.0 / 36.7 / 14.8
    for (auto [z0, sigma] : {std::pair{70.0, 1.0}, {110.0, 1.0}, {60.0, 2.0}}) {
        std::vector<double> e_ukf, e_flat, e_plain;
        for (uint32_t seed = 0; seed < 40; ++seed) {
            const Approach a = approach(seed, z0, -9.0, 150, sigma);
            const hw::RoadPoint first = invert(a.obs[0](0), a.obs[0](1));
            const double sz = first.z_m * first.z_m / (cam.fy * cam.height_m) * 2 * sigma;
            const Mat P0 = Vec((Vec(4) << 0.5, sz * sz, 100.0, 100.0).finished()).asDiagonal();
            const Vec x0 = (Vec(4) << first.x_m, first.z_m, 0, 0).finished();
            const auto xs = run_ukf({}, x0, P0, Q, sigma * sigma * Mat::Identity(2, 2), pinhole(2), a.obs);
            const auto flat = flat_road_kf(a.obs, sigma, Q, P0);
            for (size_t k = 30; k < a.obs.size(); ++k) {
                e_ukf.push_back(xs[k](3) - a.rate);
                e_flat.push_back(flat[k] - a.rate);
                // the rate from the inverted ranges 10 frames (a third of a second) apart
                const double dz = invert(a.obs[k](0), a.obs[k](1)).z_m - invert(a.obs[k - 10](0), a.obs[k - 10](1)).z_m;
                e_plain.push_back(dz / (10 * kDt) - a.rate);
            }
        }
        INFO("z0 ", z0, " m, ", sigma, " px: RMSE ukf ", rmse(e_ukf), " flat_kf ", rmse(e_flat), " plain ", rmse(e_plain));
        CHECK(rmse(e_ukf) < 0.2 * rmse(e_plain));
        CHECK(rmse(e_ukf) <= 1.0 * rmse(e_flat));
    }
}

TEST_CASE("UKF expansion observation removes the rate bias of a low contact row") {
    // The phd tracker's second observation: the feature cloud's image expansion e = -(dZ/dt)/Z. A contact row b px
    // low puts the range short by Z^2 b / (fy h) and biases the rate by 2 Z (dZ/dt) b / (fy h); with the expansion
    // the rate is e Z, short only by the range's share Z b / (fy h): half the bias.
    const hw::CameraParams cam = camera();
    const Mat Q = white_accel(1.5, 1.5);
    double r[2];
    for (int with_e = 0; with_e < 2; ++with_e) {
        std::vector<double> errs;
        for (uint32_t seed = 0; seed < 20; ++seed) {
            Approach a = approach(seed, 60.0, -10.0, 120, 0.3);
            std::mt19937 rng(seed + 1000);
            std::normal_distribution<double> e_noise(0.0, 0.03);  // 1/s; 0.001 in scale per frame
            std::vector<Vec> z;
            for (size_t k = 0; k < a.obs.size(); ++k) {
                Vec zk(with_e ? 3 : 2);
                zk(0) = a.obs[k](0);
                zk(1) = a.obs[k](1) + 1.0;  // the bottom edge one pixel low
                if (with_e) zk(2) = -a.rate / a.Z[k] + e_noise(rng);
                z.push_back(zk);
            }
            const hw::RoadPoint first = invert(z[0](0), z[0](1));
            const double sz = first.z_m * first.z_m / (cam.fy * cam.height_m);
            const Mat P0 = Vec((Vec(4) << 0.5, sz * sz, 100.0, 100.0).finished()).asDiagonal();
            Mat R = 0.09 * Mat::Identity(with_e ? 3 : 2, with_e ? 3 : 2);
            if (with_e) R(2, 2) = 0.03 * 0.03;
            const auto xs = run_ukf({}, (Vec(4) << first.x_m, first.z_m, 0, 0).finished(), P0, Q, R,
                                    pinhole(with_e ? 3 : 2), z);
            for (size_t k = 30; k < xs.size(); ++k) errs.push_back(xs[k](3) - a.rate);
        }
        r[with_e] = rmse(errs);
    }
    // measured: 0.90 m/s without, 0.62 m/s with (20 approaches 60 -> 20 m at 10 m/s, 0.3 px noise)
    INFO("range-rate RMSE after 1 s, contact row 1 px low: without ", r[0], " m/s, with ", r[1], " m/s");
    CHECK(r[1] < 0.75 * r[0]);
}

TEST_CASE("UKF covariance shrinks with each observation; a sigma point seen behind the camera leaves the state") {
    const hw::CameraParams cam = camera();
    const Vec x0 = (Vec(4) << 0.0, 40.0, 0.0, -5.0).finished();
    Ukf f({}, x0, Vec((Vec(4) << 1.0, 25.0, 25.0, 25.0).finished()).asDiagonal());
    const cv::Point2d p = hw::project_road_point(cam, 0.0, 38.0, cam.horizon_row());
    double last = f.P()(1, 1);
    for (int k = 0; k < 5; ++k) {
        REQUIRE(f.update(pinhole(2), (Vec(2) << p.x, p.y).finished(), Mat::Identity(2, 2)));
        CHECK(f.P()(1, 1) < last);
        last = f.P()(1, 1);
    }
    // the range converges to the observed one: within 0.5 m of 38 m after five 1-px observations
    CHECK(std::abs(f.x()(1) - 38.0) < 0.5);
    const Vec before = f.x();
    // a range so uncertain that sigma points fall behind the camera: project_road_point gives NaN there
    f.P()(1, 1) = 40.0 * 40.0 * 4;
    const Mat P_before = f.P();
    CHECK_FALSE(f.update(pinhole(2), (Vec(2) << p.x, p.y).finished(), Mat::Identity(2, 2)));
    CHECK((f.x() - before).norm() == 0.0);
    CHECK((f.P() - P_before).norm() == 0.0);
}
