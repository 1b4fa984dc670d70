// phd/ukf.hpp - unscented Kalman filter with scaled sigma points (Julier 2002; Wan & van der Merwe 2000),
// for any transition x' = f(x, dt) and observation z = h(x); paper 004 (eq. 16-21) uses it with the
// state [lateral X, range Z, dX/dt, dZ/dt], constant velocity (eq. 19) and the pinhole observation.
//
// Sigma points of (x, P), n states: lambda = alpha^2 (n + kappa) - n,
//     X_0 = x,  X_i = x + (sqrt((n + lambda) P))_i,  X_{n+i} = x - (sqrt((n + lambda) P))_i
//     Wm_0 = lambda / (n + lambda),  Wc_0 = Wm_0 + 1 - alpha^2 + beta,  Wm_i = Wc_i = 1 / (2 (n + lambda))
// (the matrix square root by Cholesky). Predict: propagate the points through f, x = sum Wm X,
// P = sum Wc (X - x)(X - x)^T + Q. Update: Y = h(X) from the predicted points, z^ = sum Wm Y,
// S = sum Wc (Y - z^)(Y - z^)^T + R, C = sum Wc (X - x)(Y - z^)^T, K = C S^-1,
// x += K (z - z^), P -= K S K^T. With a linear f and h this is exactly the Kalman filter.
#pragma once

#include "base/params.hpp"

#include <Eigen/Dense>

#include <functional>

namespace hw {

struct UkfParams {
    double alpha = 1.0;   // spread of the sigma points around the mean
    double beta = 2.0;    // prior knowledge of the distribution (2 is optimal for a Gaussian)
    double kappa = 0.0;   // secondary scaling

    void bind(ParamMap &m);
};

class Ukf {
public:
    using Vec = Eigen::VectorXd;
    using Mat = Eigen::MatrixXd;
    using Transition = std::function<Vec(const Vec &x, double dt)>;
    using Observation = std::function<Vec(const Vec &x)>;

    Ukf(const UkfParams &p, const Vec &x0, const Mat &P0) : p_(p), x_(x0), P_(P0) {}

    void predict(const Transition &f, double dt, const Mat &Q);
    // Returns false (state unchanged) if the innovation covariance is not positive definite or the
    // observation of a sigma point is not finite (e.g. a range behind the camera).
    bool update(const Observation &h, const Vec &z, const Mat &R);
    // Innovation z - z^ and its covariance S for a candidate z, without updating (gating).
    bool innovation(const Observation &h, const Vec &z, const Mat &R, Vec &nu, Mat &S) const;

    const Vec &x() const { return x_; }
    const Mat &P() const { return P_; }
    Vec &x() { return x_; }
    Mat &P() { return P_; }

private:
    bool sigma_points(Mat &X, Vec &wm, Vec &wc) const;
    bool observe(const Observation &h, const Vec &z, const Mat &R, Mat &X, Vec &wm, Vec &wc, Mat &Y, Vec &zhat,
                 Mat &S) const;

    UkfParams p_;
    Vec x_;
    Mat P_;
};

} // namespace hw
