#include "track/phd/ukf.hpp"

#include <cmath>

namespace hw {

void UkfParams::bind(ParamMap &m) {
    m.add("alpha", alpha, 1e-4, 10.0,
          "alpha; spread of the sigma points around the mean (lambda = alpha^2 (n + kappa) - n); small values "
          "make a 4-state filter's weights huge and of both signs");
    m.add("beta", beta, 0.0, 10.0, "beta; prior knowledge of the state distribution, 2 is optimal for a Gaussian");
    m.add("kappa", kappa, -3.0, 100.0, "kappa; secondary scaling of the sigma points (0: the usual choice for n = 4)");
}

bool Ukf::sigma_points(Mat &X, Vec &wm, Vec &wc) const {
    const int n = int(x_.size());
    const double lambda = p_.alpha * p_.alpha * (n + p_.kappa) - n;
    if (!(n + lambda > 0.0)) return false;
    const Eigen::LLT<Mat> llt((n + lambda) * P_);
    if (llt.info() != Eigen::Success) return false;
    const Mat L = llt.matrixL();
    X.resize(n, 2 * n + 1);
    X.col(0) = x_;
    for (int i = 0; i < n; ++i) {
        X.col(1 + i) = x_ + L.col(i);
        X.col(1 + n + i) = x_ - L.col(i);
    }
    wm = Vec::Constant(2 * n + 1, 0.5 / (n + lambda));
    wc = wm;
    wm(0) = lambda / (n + lambda);
    wc(0) = wm(0) + 1.0 - p_.alpha * p_.alpha + p_.beta;
    return true;
}

void Ukf::predict(const Transition &f, double dt, const Mat &Q) {
    Mat X;
    Vec wm, wc;
    if (!sigma_points(X, wm, wc)) {  // P lost definiteness: restore it by symmetrising and bounding
        P_ = 0.5 * (P_ + P_.transpose()) + 1e-9 * Mat::Identity(P_.rows(), P_.cols());
        if (!sigma_points(X, wm, wc)) return;
    }
    for (int i = 0; i < X.cols(); ++i) X.col(i) = f(X.col(i), dt);
    x_ = X * wm;
    P_ = Q;
    for (int i = 0; i < X.cols(); ++i) {
        const Vec d = X.col(i) - x_;
        P_ += wc(i) * d * d.transpose();
    }
}

bool Ukf::observe(const Observation &h, const Vec &z, const Mat &R, Mat &X, Vec &wm, Vec &wc, Mat &Y, Vec &zhat,
                  Mat &S) const {
    if (!sigma_points(X, wm, wc)) return false;
    Y.resize(z.size(), X.cols());
    for (int i = 0; i < X.cols(); ++i) {
        Y.col(i) = h(X.col(i));
        if (!Y.col(i).allFinite()) return false;
    }
    zhat = Y * wm;
    S = R;
    for (int i = 0; i < Y.cols(); ++i) {
        const Vec d = Y.col(i) - zhat;
        S += wc(i) * d * d.transpose();
    }
    return true;
}

bool Ukf::innovation(const Observation &h, const Vec &z, const Mat &R, Vec &nu, Mat &S) const {
    Mat X, Y;
    Vec wm, wc, zhat;
    if (!observe(h, z, R, X, wm, wc, Y, zhat, S)) return false;
    nu = z - zhat;
    return true;
}

bool Ukf::update(const Observation &h, const Vec &z, const Mat &R) {
    Mat X, Y, S;
    Vec wm, wc, zhat;
    if (!observe(h, z, R, X, wm, wc, Y, zhat, S)) return false;
    Mat C = Mat::Zero(x_.size(), z.size());
    for (int i = 0; i < X.cols(); ++i) C += wc(i) * (X.col(i) - x_) * (Y.col(i) - zhat).transpose();
    const Eigen::LLT<Mat> s_llt(S);
    if (s_llt.info() != Eigen::Success) return false;
    const Mat K = s_llt.solve(C.transpose()).transpose();  // C S^-1 (S symmetric)
    x_ += K * (z - zhat);
    P_ -= K * S * K.transpose();
    P_ = 0.5 * (P_ + P_.transpose());
    return true;
}

} // namespace hw
