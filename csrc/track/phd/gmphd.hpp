// phd/gmphd.hpp - Gaussian-mixture probability hypothesis density (GM-PHD) filter on 2-D image points
// (paper 004, eq. 3-12; Vo & Ma 2006 for the recursion the paper follows).
//
// The intensity of "a feature point here" is a sum of weighted Gaussians w_j N(x; m_j, P_j) over the
// image plane (x = [u, v] in px). Its integral (the weight sum) is the expected number of features.
//   Prediction (eq. 6, no spawning): every component survives with probability q_k and moves with the
//     vehicle's image motion x' = c + t + s (x - c) (scale s about centre c, shift t; identity in the
//     paper's static case): m' = c + t + s (m - c), P' = s^2 P + Q, w' = q_k w. Births (eq. 7) are
//     added as N(m_b, P_b) with weight w_b, each candidate admitted with probability P_clutter.
//   Update (eq. 3-5) with the measurement set Z:
//     missed:   w (1 - P_D),  same m, P
//     for z:    w_j(z) = P_D w_j q_j(z) / (kappa + P_D sum_l w_l q_l(z)),  q_j(z) = N(z; m_j, P_j + R)
//               m_j(z) = m_j + K_j (z - m_j),  P_j(z) = (I - K_j) P_j,  K_j = P_j (P_j + R)^-1
//   Merging (eq. 9-11): components within a Mahalanobis distance U of the strongest one, or within a
//     circle of merge_radius px in the image (the paper's circular gating), become one:
//     w = sum w_i, m = sum w_i m_i / w, P = sum w_i (P_i + (m - m_i)(m - m_i)^T) / w.
//   Pruning (eq. 8, adaptive): components under the threshold T are dropped, unless fewer than J_min
//     would remain: then the threshold falls to the J_min-th largest weight (the paper's "adaptive
//     threshold" keeps a minimum number of features; its formula is unreadable in our copy of the
//     paper, this is our reading of the text around it). At most max_components are kept (strongest).
//   A vehicle is gone (eq. 12) when the weight summed inside its box falls under a threshold.
#pragma once

#include "base/params.hpp"

#include <opencv2/core.hpp>

#include <cstdint>
#include <random>
#include <vector>

namespace hw {

struct GmPhdParams {
    double survival_prob = 0.99;       // q_k: a feature survives one frame (eq. 4, 6)
    double detection_prob = 0.9;       // P_D: a surviving feature is measured (tracked by LK) this frame
    double clutter_density = 5e-4;     // kappa: clutter measurements per px^2 (eq. 4)
    double meas_sigma_px = 0.7;        // px; 1-sigma of a measured feature position (R = sigma^2 I)
    double process_sigma_px = 1.0;     // px; 1-sigma per frame of a feature's motion not explained by the vehicle's
    double birth_weight = 0.01;        // w_b: weight of a new feature (eq. 7)
    double birth_sigma_px = 3.0;       // px; 1-sigma of a new feature's position (P_b = sigma^2 I)
    double birth_accept_prob = 0.7;    // P_clutter: share of the candidate births admitted (drawn at random)
    double merge_mahalanobis = 4.0;    // U: components closer than this (squared Mahalanobis) merge (eq. 9-11)
    double merge_radius_px = 2.0;      // px; the paper's circular gate: components closer in the image merge
    double prune_weight = 0.02;        // T: components lighter than this are dropped (eq. 8) ...
    int min_components = 8;            // J_min: ... unless fewer than this would remain
    int max_components = 40;           // cap on the components kept after pruning (cost bound)
    double truncate_weight = 1e-5;     // weights below this are numerical dust, dropped before merging
    double update_gate_sigma = 5.0;    // a measurement further than this many sigmas updates no component (0 = all)
    double stable_weight = 0.5;        // a component this heavy is a stable feature (used for the vehicle)

    void bind(ParamMap &m);
};

struct GmComponent {
    double w = 0.0;
    cv::Vec2d m;                 // mean, px
    cv::Matx22d P;               // covariance, px^2
    cv::Vec2d tag{0, 0};         // the user's 2-vector carried with the feature (the phd tracker: its offset from
                                 // the vehicle's contact point in vehicle widths); merged as a weighted mean
};

class GmPhd {
public:
    explicit GmPhd(const GmPhdParams &p, uint32_t seed = 1) : p_(p), rng_(seed) {}

    // Eq. 6 without spawning: survival and the vehicle's image motion x' = c + t + s (x - c).
    void predict(double scale = 1.0, cv::Vec2d centre = {0, 0}, cv::Vec2d shift = {0, 0});
    // Eq. 7: each candidate admitted with probability birth_accept_prob; returns how many were.
    // tags: one per candidate, or empty (zero tags).
    int add_births(const std::vector<cv::Vec2d> &candidates, const std::vector<cv::Vec2d> &tags = {});
    // A birth with no random draw (tests, or a vehicle's first features).
    void add_birth(const cv::Vec2d &m, const cv::Vec2d &tag = {0, 0});
    // Eq. 3-5 with the measurement set Z.
    void update(const std::vector<cv::Vec2d> &Z);
    // Eq. 9-11, then eq. 8 and the cap.
    void merge_and_prune();

    // Eq. 12: weight summed over the components whose mean lies inside `box`.
    double weight_in(const cv::Rect2d &box) const;
    double weight_sum() const;
    const std::vector<GmComponent> &components() const { return comps_; }
    std::vector<GmComponent> &components() { return comps_; }
    void clear() { comps_.clear(); }
    const GmPhdParams &params() const { return p_; }

private:
    GmPhdParams p_;
    std::mt19937 rng_;
    std::vector<GmComponent> comps_;
};

} // namespace hw
