#include "track/phd/gmphd.hpp"

#include <algorithm>
#include <cmath>

namespace hw {

void GmPhdParams::bind(ParamMap &m) {
    m.add("survival_prob", survival_prob, 0.0, 1.0,
          "q_k (eq. 4, 6); probability that a feature survives one frame; features leave mostly by failing "
          "their measurement, so close to 1");
    m.add("detection_prob", detection_prob, 0.0, 1.0,
          "P_D (eq. 4); probability that a surviving feature is measured (LK tracked and consistent with the "
          "vehicle's motion); a missed component keeps (1 - P_D) of its weight");
    m.add("clutter_density", clutter_density, 1e-12, 1.0,
          "kappa (eq. 4); clutter measurements per px^2 (about 5 spurious corners in a 100 x 100 px box); a new "
          "feature needs two consecutive frames to become stable (docs/tracking.md)");
    m.add("meas_sigma_px", meas_sigma_px, 0.01, 50.0,
          "px; 1-sigma error of a measured feature position, R = sigma^2 I (eq. 5); LK is sub-pixel");
    m.add("process_sigma_px", process_sigma_px, 0.0, 50.0,
          "px; 1-sigma per frame of a feature's motion that the vehicle's image motion (shift and scale) does "
          "not explain, Q = sigma^2 I");
    m.add("birth_weight", birth_weight, 1e-6, 1.0,
          "w_b (eq. 7); weight of a new feature, small so that a feature seen in one frame never becomes stable "
          "and clutter adds little to the count (docs/tracking.md)");
    m.add("birth_sigma_px", birth_sigma_px, 0.01, 100.0, "px; 1-sigma of a new feature's position, P_b = sigma^2 I (eq. 7)");
    m.add("birth_accept_prob", birth_accept_prob, 0.0, 1.0,
          "P_clutter; each candidate birth is admitted with this probability (drawn at random, seeded per "
          "vehicle): the paper's way to leave out part of the clutter and bound the cost");
    m.add("merge_mahalanobis", merge_mahalanobis, 0.0, 1000.0,
          "U; components within this squared Mahalanobis distance of a stronger one merge into it (eq. 9-11)");
    m.add("merge_radius_px", merge_radius_px, 0.0, 100.0,
          "px; the paper's circular gate: components closer than this in the image merge as well (corners "
          "come in clusters on a vehicle)");
    m.add("prune_weight", prune_weight, 0.0, 1.0,
          "T (eq. 8); components lighter than this are dropped: a stable feature missed once (weight x (1 - P_D) "
          "= 0.1) is kept for its next measurement, missed twice it goes; a one-frame feature goes the frame after");
    m.add("min_components", min_components, 0, 10000,
          "J_min (eq. 8); the pruning threshold adapts down so that at least this many components remain "
          "(new births then get the chance to replace lost features)");
    m.add("max_components", max_components, 1, 10000,
          "cap on the components kept after merging and pruning (the strongest); bounds the cost of the "
          "update, which is components x measurements");
    m.add("truncate_weight", truncate_weight, 0.0, 1.0,
          "weights below this are numerical dust and dropped before merging (merging is quadratic in the count)");
    m.add("update_gate_sigma", update_gate_sigma, 0.0, 100.0,
          "sigmas; a (component, measurement) pair further apart than this is not evaluated (its likelihood "
          "is below 4e-6 of the peak at 5); 0 evaluates every pair");
    m.add("stable_weight", stable_weight, 0.0, 10.0,
          "a component at least this heavy is a stable feature: it is reported and used for the vehicle's "
          "position (eq. 13-15)");
}

void GmPhd::predict(double s, cv::Vec2d c, cv::Vec2d t) {
    const double q = p_.process_sigma_px * p_.process_sigma_px;
    for (GmComponent &g : comps_) {
        g.w *= p_.survival_prob;
        g.m = c + t + s * (g.m - c);
        g.P = s * s * g.P + cv::Matx22d(q, 0, 0, q);
    }
}

void GmPhd::add_birth(const cv::Vec2d &m, const cv::Vec2d &tag) {
    const double b = p_.birth_sigma_px * p_.birth_sigma_px;
    comps_.push_back({p_.birth_weight, m, cv::Matx22d(b, 0, 0, b), tag});
}

int GmPhd::add_births(const std::vector<cv::Vec2d> &candidates, const std::vector<cv::Vec2d> &tags) {
    std::uniform_real_distribution<double> u(0.0, 1.0);
    int n = 0;
    for (size_t i = 0; i < candidates.size(); ++i)
        if (u(rng_) < p_.birth_accept_prob) {
            add_birth(candidates[i], i < tags.size() ? tags[i] : cv::Vec2d(0, 0));
            ++n;
        }
    return n;
}

void GmPhd::update(const std::vector<cv::Vec2d> &Z) {
    const size_t J = comps_.size();
    const double r = p_.meas_sigma_px * p_.meas_sigma_px;
    const double gate2 = p_.update_gate_sigma * p_.update_gate_sigma;
    // Per component: S = P + R, its inverse, the normalisation and the gain (eq. 5).
    struct Pre { cv::Matx22d Si, K, Pu; double norm; };
    std::vector<Pre> pre(J);
    for (size_t j = 0; j < J; ++j) {
        const cv::Matx22d S = comps_[j].P + cv::Matx22d(r, 0, 0, r);
        const double det = S(0, 0) * S(1, 1) - S(0, 1) * S(1, 0);
        pre[j].Si = cv::Matx22d(S(1, 1), -S(0, 1), -S(1, 0), S(0, 0)) * (1.0 / det);
        pre[j].norm = 1.0 / (2.0 * M_PI * std::sqrt(det));
        pre[j].K = comps_[j].P * pre[j].Si;
        pre[j].Pu = (cv::Matx22d::eye() - pre[j].K) * comps_[j].P;
    }
    std::vector<GmComponent> out;
    out.reserve(J * (1 + std::min<size_t>(Z.size(), 4)));
    for (const GmComponent &g : comps_) out.push_back({g.w * (1.0 - p_.detection_prob), g.m, g.P, g.tag});
    std::vector<GmComponent> for_z;
    for (const cv::Vec2d &z : Z) {
        for_z.clear();
        double sum = 0.0;
        for (size_t j = 0; j < J; ++j) {
            const cv::Vec2d d = z - comps_[j].m;
            const double d2 = d.dot(pre[j].Si * d);
            if (gate2 > 0.0 && d2 > gate2) continue;
            const double wz = p_.detection_prob * comps_[j].w * pre[j].norm * std::exp(-0.5 * d2);
            sum += wz;
            for_z.push_back({wz, comps_[j].m + pre[j].K * d, pre[j].Pu, comps_[j].tag});
        }
        const double den = p_.clutter_density + sum;
        for (GmComponent &g : for_z) {
            g.w /= den;
            out.push_back(g);
        }
    }
    comps_.swap(out);
}

void GmPhd::merge_and_prune() {
    // Numerical dust first, then merge the strongest with everything of the same feature.
    comps_.erase(std::remove_if(comps_.begin(), comps_.end(),
                                [&](const GmComponent &g) { return !(g.w >= p_.truncate_weight); }),
                 comps_.end());
    std::sort(comps_.begin(), comps_.end(), [](const GmComponent &a, const GmComponent &b) { return a.w > b.w; });
    const double r2 = p_.merge_radius_px * p_.merge_radius_px;
    std::vector<bool> taken(comps_.size(), false);
    std::vector<cv::Matx22d> inv(comps_.size());
    for (size_t k = 0; k < comps_.size(); ++k) {
        const cv::Matx22d &P = comps_[k].P;
        inv[k] = cv::Matx22d(P(1, 1), -P(0, 1), -P(1, 0), P(0, 0)) * (1.0 / (P(0, 0) * P(1, 1) - P(0, 1) * P(1, 0)));
    }
    std::vector<GmComponent> merged;
    std::vector<size_t> M;
    for (size_t i = 0; i < comps_.size(); ++i) {
        if (taken[i]) continue;
        const GmComponent &lead = comps_[i];
        M.clear();
        for (size_t k = i; k < comps_.size(); ++k) {
            if (taken[k]) continue;
            // Vo & Ma: (m_i - m_k)^T P_k^-1 (m_i - m_k) <= U, or the circular image gate
            const cv::Vec2d d = comps_[k].m - lead.m;
            if (d.dot(d) <= r2 || d.dot(inv[k] * d) <= p_.merge_mahalanobis) {
                M.push_back(k);
                taken[k] = true;
            }
        }
        GmComponent g;  // eq. 9-11
        g.m = {0, 0};
        g.P = cv::Matx22d::zeros();
        for (size_t k : M) {
            g.w += comps_[k].w;
            g.m += comps_[k].w * comps_[k].m;
            g.tag += comps_[k].w * comps_[k].tag;
        }
        g.m *= 1.0 / g.w;
        g.tag *= 1.0 / g.w;
        for (size_t k : M) {
            const cv::Vec2d d = g.m - comps_[k].m;
            g.P += comps_[k].w * (comps_[k].P + d * d.t());
        }
        g.P *= 1.0 / g.w;
        merged.push_back(g);
    }
    // Eq. 8, adaptive: the threshold falls to the J_min-th weight when fewer would pass; then the cap.
    std::sort(merged.begin(), merged.end(), [](const GmComponent &a, const GmComponent &b) { return a.w > b.w; });
    size_t keep = 0;
    while (keep < merged.size() && merged[keep].w >= p_.prune_weight) ++keep;
    keep = std::max(keep, std::min(merged.size(), size_t(p_.min_components)));
    keep = std::min(keep, size_t(p_.max_components));
    merged.resize(keep);
    comps_.swap(merged);
}

double GmPhd::weight_in(const cv::Rect2d &box) const {
    double s = 0.0;
    for (const GmComponent &g : comps_)
        if (g.m[0] >= box.x && g.m[0] <= box.x + box.width && g.m[1] >= box.y && g.m[1] <= box.y + box.height) s += g.w;
    return s;
}

double GmPhd::weight_sum() const {
    double s = 0.0;
    for (const GmComponent &g : comps_) s += g.w;
    return s;
}

} // namespace hw
