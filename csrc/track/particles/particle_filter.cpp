#include "track/particles/particle_filter.hpp"

#include "track/duplicate_pruning.hpp"

#include <algorithm>
#include <cmath>
#include <numeric>

namespace hw {

void ParticleParams::bind(ParamMap &m) {
    m.add("particles", particles, 10, 100000,
          "n_s; particles of the joint filter; the cost per frame is proportional to n_s * N * (M + 1); 500 keeps "
          "eight vehicles well inside a millisecond");
    m.add("reserve_share", reserve_share, 0.01, 0.9,
          "n_r / n_s: share of the particles that get the extra vehicle when a transitory period starts");
    m.add("end_share", end_share, 0.001, 0.49,
          "the transitory period ends when the N- or the (N+1)-particles fall below this share: the hypothesised "
          "vehicle is then confirmed or forgotten");
    m.add("max_transitory_frames", max_transitory_frames, 1, 1000,
          "frames; a period still undecided after this long is decided by the majority");
    m.add("a_u", a_u, 0.0, 1.0,
          "mixing coefficient of the uniform clutter term in the stationary state (measurements explained by "
          "noise rather than a vehicle)");
    m.add("a_u_transitory", a_u_transitory, 0.0, 1.0,
          "clutter coefficient during a transitory period, raised so that only persistent, coherent "
          "measurements make a new vehicle (paper III-B; docs/tracking.md)");
    m.add("p_detect", p_detect, 0.0, 0.999,
          "detection probability: each vehicle no measurement supports multiplies a particle's weight by "
          "1 - p_detect; this is what lets unsupported hypotheses fade");
    m.add("meas_sigma_x_frac", meas_sigma_x_frac, 0.0, 2.0,
          "vehicle widths; 1-sigma error of a measurement's column for that vehicle (region ends are blurred by "
          "spill and wheels)");
    m.add("meas_sigma_y_frac", meas_sigma_y_frac, 0.0, 2.0, "vehicle widths; 1-sigma error of a measurement's bottom row");
    m.add("meas_sigma_min_px", meas_sigma_min_px, 0.1, 100.0, "px; floor of both measurement sigmas");
    m.add("accel_widths_s2", accel_widths_s2, 0.0, 100.0,
          "vehicle widths / s^2; random image acceleration of a vehicle (a 1.8 m car braking at 3.6 m/s^2 is 2 "
          "widths/s^2)");
    m.add("ego_accel_px_s2", ego_accel_px_s2, 0.0, 1e5,
          "px / s^2; image acceleration of every vehicle from the ego's pitch and yaw shake");
    m.add("init_speed_px_s", init_speed_px_s, 0.0, 1e4,
          "px / s; velocity spread of a hypothesised vehicle (vehicles entering from the side cross the image at "
          "100-300 px/s)");
    m.add("gate_sigma", gate_sigma, 0.5, 20.0,
          "Mahalanobis distance beyond which a measurement is explained by no vehicle (it may start a transitory "
          "period) and does not update a vehicle's box");
    m.add("size_alpha", size_alpha, 0.0, 1.0,
          "smoothing gain of a vehicle's box width and height from the measurement regions near it");
    m.add("max_vehicles", max_vehicles, 1, 64, "N at most; bounds the cost");
    m.add("max_measurements", max_measurements, 1, 256,
          "measurements used per frame at most, strongest first; bounds the cost");
    m.add("max_missed_frames", max_missed_frames, 1, 10000,
          "frames; a vehicle no measurement came near for this long is removed (it stopped showing parallax)");
    // A vehicle's support is the running average of "a measurement came near it this frame".
    m.add("support_alpha", support_alpha, 0.0, 1.0, "gain of a vehicle's support (running average, see above)");
    m.add("min_support", min_support, 0.0, 1.0,
          "a vehicle whose support falls below this is removed (once min_support_age old): an artifact that now "
          "and then lands near it keeps no ghost alive, while a vehicle measured in most frames stays");
    m.add("min_support_age", min_support_age, 0, 10000, "frames; age before the support rule applies");
    m.add("roi_margin_px", roi_margin_px, -1000.0, 1000.0,
          "px; a vehicle whose estimate is this far outside the image (or at the horizon) has left");
    m.add("duplicate_frac", duplicate_frac, 0.0, 2.0,
          "vehicle widths; two vehicles whose estimates are this close follow one vehicle: the younger goes");
    m.add("border_frac", border_frac, 0.0, 10.0,
          "vehicle widths; a hypothesis whose box reaches this near the image's side has its lateral speed "
          "judged only once it is in full view (an entering car; docs/tracking.md)");
    m.add("max_lateral_mps", max_lateral_mps, 0.1, 100.0,
          "m/s; a hypothesis whose image motion means moving sideways on the road faster than this is a chain of "
          "artifacts, not a vehicle (a lane change is ~2 m/s)");
    m.add("max_closing_mps", max_closing_mps, 1.0, 1000.0,
          "m/s; nor one whose range would change faster than this (two cars at 250 km/h head-on: 140)");
    m.add("seed", seed, 0, 2147483647, "random seed of the filter; runs are reproducible");
    m.add("resampling", resampling, "joint|per_vehicle",
          "joint: the paper's, each particle resampled whole by its joint weight; per_vehicle: each vehicle's "
          "part resampled by its own factor (docs/tracking.md)");
    m.add("max_dt_s", max_dt_s, 0.01, 100.0,
          "s; a longer gap between frames (or time going back) drops all vehicles and starts the filter again");
}

JointParticleFilter::JointParticleFilter(const ParticleParams &p, const CameraParams &cam)
    : p_(p), cam_(cam), per_vehicle_(p.resampling == "per_vehicle"), rng_(uint32_t(p.seed)) {
    reset();
}

bool JointParticleFilter::plausible(const Vehicle &v, cv::Point2f vp) const {
    const double dy = double(v.mean[1]) - vp.y;
    if (dy <= 1.0) return false;
    const double fh = cam_.fy * cam_.height_m;
    const double Z = fh / dy, X = (double(v.mean[0]) - vp.x) * Z / cam_.fx;
    const double dZ = -double(v.mean[3]) * Z * Z / fh;                      // dZ/dt = -vy Z^2 / (fy h)
    const double dX = (double(v.mean[2]) + cam_.fx * X * dZ / (Z * Z)) * Z / cam_.fx;  // from vx
    return std::fabs(dX) <= p_.max_lateral_mps && std::fabs(dZ) <= p_.max_closing_mps;
}

void JointParticleFilter::reset() {
    vehicles_.clear();
    candidate_ = Vehicle{};
    transitory_frames_ = 0;
    state_.assign(size_t(p_.particles) * 4, 0.f);
    extended_.assign(size_t(p_.particles), 0);
    logw_.assign(size_t(p_.particles), 0.0);
    rng_.seed(uint32_t(p_.seed));
    next_id_ = 1;
}

void JointParticleFilter::propagate(double dt) {
    std::normal_distribution<float> n01(0.f, 1.f);
    const int N = int(vehicles_.size());
    const float t = float(dt), t2 = 0.5f * t * t;
    auto sigma_a = [&](float w) {
        return std::sqrt(float(p_.accel_widths_s2 * p_.accel_widths_s2) * w * w +
                         float(p_.ego_accel_px_s2 * p_.ego_accel_px_s2));
    };
    std::vector<float> sa(size_t(N) + 1);
    for (int i = 0; i < N; ++i) sa[size_t(i)] = sigma_a(vehicles_[size_t(i)].w);
    sa[size_t(N)] = sigma_a(candidate_.w);
    for (int s = 0; s < p_.particles; ++s) {
        float *x = particle(s);
        const int nv = N + (extended_[size_t(s)] ? 1 : 0);
        for (int i = 0; i < nv; ++i, x += 4) {
            // x' = x + vx dt + a dt^2 / 2, vx' = vx + a dt
            const float ax = sa[size_t(i)] * n01(rng_), ay = sa[size_t(i)] * n01(rng_);
            x[0] += x[2] * t + ax * t2;
            x[1] += x[3] * t + ay * t2;
            x[2] += ax * t;
            x[3] += ay * t;
        }
    }
}

void JointParticleFilter::weigh(const std::vector<PointMeasurement> &z, cv::Size image) {
    const int N = int(vehicles_.size());
    const double a_u = transitory() ? p_.a_u_transitory : p_.a_u;
    const double U = 1.0 / (double(image.width) * double(image.height));  // uniform clutter density
    const double pd = p_.p_detect;
    // p_i is vehicle i's own measurement model: its sigmas scale with its width (a wide artifact region
    // must not pass for a near measurement of every vehicle).
    struct Sig { float ix, iy; double norm; };
    std::vector<Sig> sig;
    for (int i = 0; i <= N; ++i) {
        const float w = i < N ? vehicles_[size_t(i)].w : candidate_.w;
        const float sx = std::max(float(p_.meas_sigma_min_px), float(p_.meas_sigma_x_frac) * w);
        const float sy = std::max(float(p_.meas_sigma_min_px), float(p_.meas_sigma_y_frac) * w);
        sig.push_back({1.f / sx, 1.f / sy, 1.0 / (2.0 * M_PI * double(sx) * double(sy))});
    }
    const int ns = p_.particles;
    const double log_clutter = std::log(a_u * U);
    std::vector<double> g(size_t(N) + 1);
    if (per_vehicle_) logf_.assign(size_t(ns) * size_t(N + 1), 0.0);
    struct Near { int i; double p; };
    std::vector<Near> near;  // the vehicles of this particle near one measurement (usually one or none)
    for (int s = 0; s < ns; ++s) {
        const float *x = particle(s);
        const int nv = N + (extended_[size_t(s)] ? 1 : 0);
        std::fill(g.begin(), g.end(), 0.0);
        double lw = 0.0;
        for (size_t j = 0; j < z.size(); ++j) {
            double sum_p = 0.0, sum_p2 = 0.0;
            near.clear();
            for (int i = 0; i < nv; ++i) {
                const float dx = (z[j].z.x - x[4 * i]) * sig[size_t(i)].ix, dy = (z[j].z.y - x[4 * i + 1]) * sig[size_t(i)].iy;
                const float d2 = dx * dx + dy * dy;
                if (d2 > 60.f) continue;  // exp(-30): nothing
                const double e = std::exp(-0.5 * double(d2));
                const double pij = e * sig[size_t(i)].norm;
                sum_p += pij;
                sum_p2 += pij * pij;
                g[size_t(i)] = std::max(g[size_t(i)], e);
                near.push_back({i, pij});
            }
            // sum_i a_ij p_ij + a_u U with a_ij = (1 - a_u) p_ij / sum_i p_ij   (eq. 2)
            const double mix = sum_p > 0.0 ? (1.0 - a_u) * sum_p2 / sum_p : 0.0;
            const double l_all = std::log(mix + a_u * U);
            lw += l_all;
            // per_vehicle: vehicle i's share of this term is the bracket with it over the bracket without
            // it (the others summed afresh, not subtracted: p_ij may dwarf them).
            if (per_vehicle_ && near.size() == 1) {  // the usual case: without it only clutter is left
                logf_[size_t(near[0].i) * size_t(ns) + size_t(s)] += l_all - log_clutter;
                continue;
            }
            for (size_t a = 0; per_vehicle_ && a < near.size(); ++a) {
                double sp = 0.0, sp2 = 0.0;
                for (size_t b = 0; b < near.size(); ++b)
                    if (b != a) { sp += near[b].p; sp2 += near[b].p * near[b].p; }
                const double mix_without = sp > 0.0 ? (1.0 - a_u) * sp2 / sp : 0.0;
                logf_[size_t(near[a].i) * size_t(ns) + size_t(s)] += l_all - std::log(mix_without + a_u * U);
            }
        }
        for (int i = 0; i < nv; ++i) {
            const double det = std::log(1.0 - pd + pd * g[size_t(i)]);  // detection term
            lw += det;
            if (per_vehicle_) logf_[size_t(i) * size_t(ns) + size_t(s)] += det;
        }
        logw_[size_t(s)] = lw;
    }
}

void JointParticleFilter::systematic(const double *logw, std::vector<int> &ancestor) {
    const int ns = p_.particles;
    ancestor.resize(size_t(ns));
    const auto [lo, hi] = std::minmax_element(logw, logw + ns);
    if (*lo == *hi) {  // equal weights (a vehicle no measurement came near): systematic keeps every particle
        std::iota(ancestor.begin(), ancestor.end(), 0);
        return;
    }
    const double mx = *hi;
    cum_.resize(size_t(ns));
    double acc = 0.0;
    for (int s = 0; s < ns; ++s) cum_[size_t(s)] = (acc += std::exp(logw[s] - mx));
    const std::vector<double> &cum = cum_;
    // One uniform offset, then n_s evenly spaced pointers into the cumulative weights.
    std::uniform_real_distribution<double> u01(0.0, 1.0);
    const double step = acc / ns;
    double u = u01(rng_) * step;
    int k = 0;
    for (int s = 0; s < ns; ++s, u += step) {
        while (k < ns - 1 && cum[size_t(k)] < u) ++k;
        ancestor[size_t(s)] = k;
    }
}

void JointParticleFilter::resample() {
    const int ns = p_.particles, N = int(vehicles_.size());
    const size_t S = size_t(stride());
    std::vector<float> next(state_.size());
    std::vector<uint8_t> ext(static_cast<size_t>(ns));
    std::vector<int> anc;
    if (!per_vehicle_) {
        systematic(logw_.data(), anc);  // the paper: whole particles by their joint weight
        for (int s = 0; s < ns; ++s) {
            const size_t k = size_t(anc[size_t(s)]);
            std::copy_n(&state_[k * S], S, &next[size_t(s) * S]);
            ext[size_t(s)] = extended_[k];
        }
    } else {
        // Each vehicle's slot by its own factor, each with its own draw; then the candidate's slot
        // together with the mark that the particle carries it.
        for (int i = 0; i <= N; ++i) {
            if (i == N && !transitory()) break;
            systematic(&logf_[size_t(i) * size_t(ns)], anc);
            for (int s = 0; s < ns; ++s) {
                const size_t k = size_t(anc[size_t(s)]);
                std::copy_n(&state_[k * S + 4 * size_t(i)], 4, &next[size_t(s) * S + 4 * size_t(i)]);
                if (i == N) ext[size_t(s)] = extended_[k];
            }
        }
    }
    state_.swap(next);
    extended_.swap(ext);
}

void JointParticleFilter::estimate() {
    const int N = int(vehicles_.size());
    auto mean_of = [&](int i, bool only_extended, Vehicle &v) {
        cv::Vec4d sum(0, 0, 0, 0);
        double sy2 = 0.0;
        int n = 0;
        for (int s = 0; s < p_.particles; ++s) {
            if (only_extended && !extended_[size_t(s)]) continue;
            const float *x = particle(s) + 4 * i;
            for (int c = 0; c < 4; ++c) sum[c] += x[c];
            sy2 += double(x[1]) * x[1];
            ++n;
        }
        if (n == 0) return;
        v.mean = cv::Vec4f(float(sum[0] / n), float(sum[1] / n), float(sum[2] / n), float(sum[3] / n));
        v.sigma_y = float(std::sqrt(std::max(0.0, sy2 / n - double(v.mean[1]) * v.mean[1])));
    };
    for (int i = 0; i < N; ++i) mean_of(i, false, vehicles_[size_t(i)]);
    if (transitory()) mean_of(N, true, candidate_);
}

void JointParticleFilter::end_transitory(cv::Point2f vp, cv::Size image) {
    if (!transitory()) return;
    ++transitory_frames_;
    const int ns = p_.particles;
    const int n_ext = int(std::count(extended_.begin(), extended_.end(), uint8_t(1)));
    const double share = double(n_ext) / ns;
    const bool decide = transitory_frames_ >= p_.max_transitory_frames;
    const bool wins = share > 1.0 - p_.end_share || (decide && share >= 0.5);
    // The sideways motion of a hypothesis cut by the image's side is not that of a vehicle: its visible
    // part widens as it enters and the mid-lower point slides with it. It is judged once in full view
    // (until then a winning hypothesis waits, up to max_transitory_frames more).
    const float half = 0.5f * candidate_.w, margin = float(p_.border_frac) * candidate_.w;
    const bool cut = candidate_.mean[0] - half <= margin || candidate_.mean[0] + half >= float(image.width - 1) - margin;
    if (wins && cut && !plausible(candidate_, vp) && transitory_frames_ < 2 * p_.max_transitory_frames) return;
    if (share < p_.end_share || (decide && share < 0.5) || (wins && !plausible(candidate_, vp))) {
        std::fill(extended_.begin(), extended_.end(), uint8_t(0));  // the hypothesis fades
        candidate_ = Vehicle{};
        transitory_frames_ = 0;
        return;
    }
    if (wins) {
        // The (N+1)-particles won: every particle gets the new vehicle (copied from one that has it).
        const int N = int(vehicles_.size());
        std::vector<int> with;
        for (int s = 0; s < ns; ++s)
            if (extended_[size_t(s)]) with.push_back(s);
        std::uniform_int_distribution<int> pick(0, int(with.size()) - 1);
        const size_t S = size_t(stride()), S2 = S + 4;
        std::vector<float> next(size_t(ns) * S2, 0.f);
        for (int s = 0; s < ns; ++s) {
            std::copy_n(&state_[size_t(s) * S], S, &next[size_t(s) * S2]);
            if (!extended_[size_t(s)])
                std::copy_n(&state_[size_t(with[size_t(pick(rng_))]) * S + 4 * size_t(N)], 4, &next[size_t(s) * S2 + 4 * size_t(N)]);
        }
        state_.swap(next);
        std::fill(extended_.begin(), extended_.end(), uint8_t(0));
        vehicles_.push_back(candidate_);
        candidate_ = Vehicle{};
        transitory_frames_ = 0;
    }
}

void JointParticleFilter::remove_vehicle(int i) {
    const size_t S = size_t(stride()), S2 = S - 4;
    std::vector<float> next(size_t(p_.particles) * S2);
    for (int s = 0; s < p_.particles; ++s) {
        const float *src = &state_[size_t(s) * S];
        float *dst = &next[size_t(s) * S2];
        std::copy_n(src, 4 * size_t(i), dst);
        std::copy(src + 4 * size_t(i) + 4, src + S, dst + 4 * size_t(i));
    }
    state_.swap(next);
    vehicles_.erase(vehicles_.begin() + i);
}

void JointParticleFilter::bookkeeping(const std::vector<PointMeasurement> &z, cv::Size image, float horizon_row) {
    // Each vehicle (and the candidate) takes its size from the nearest measurement within the gate.
    auto update = [&](Vehicle &v) {
        int best = -1;
        float best_d2 = float(p_.gate_sigma * p_.gate_sigma);
        const float sx = std::max(float(p_.meas_sigma_min_px), float(p_.meas_sigma_x_frac) * v.w);
        const float sy = std::max(float(p_.meas_sigma_min_px), float(p_.meas_sigma_y_frac) * v.w);
        for (size_t j = 0; j < z.size(); ++j) {
            const float dx = (z[j].z.x - v.mean[0]) / sx, dy = (z[j].z.y - v.mean[1]) / sy;
            if (dx * dx + dy * dy < best_d2) { best_d2 = dx * dx + dy * dy; best = int(j); }
        }
        ++v.age;
        // support: a slow average of "measured this frame"
        v.support += float(p_.support_alpha) * ((best >= 0 ? 1.f : 0.f) - v.support);
        if (best < 0) { ++v.missed; return; }
        v.missed = 0;
        ++v.hits;
        const float a = float(p_.size_alpha);
        v.w += a * (z[size_t(best)].box.width - v.w);
        v.h += a * (z[size_t(best)].box.height - v.h);
    };
    for (auto &v : vehicles_) update(v);
    if (transitory()) update(candidate_);

    // Exits: out of the image, up at the horizon, or unsupported for too long.
    const float m = float(p_.roi_margin_px);
    for (int i = int(vehicles_.size()) - 1; i >= 0; --i) {
        const Vehicle &v = vehicles_[size_t(i)];
        const bool out = v.mean[0] < -m || v.mean[0] > float(image.width) + m || v.mean[1] > float(image.height) + m ||
                         v.mean[1] < horizon_row + 2.f;
        const bool unsupported = v.age >= p_.min_support_age && v.support < float(p_.min_support);
        if (out || v.missed > p_.max_missed_frames || unsupported) remove_vehicle(i);
    }
    // Two vehicles on one: the one measured fewer times goes.
    std::vector<TrackRank> ranks;
    for (const Vehicle &v : vehicles_) ranks.push_back({v.id, v.hits});
    const std::vector<bool> twice = duplicate_tracks(ranks, [&](size_t i, size_t k) {
        const Vehicle &a = vehicles_[i], &b = vehicles_[k];
        const float lim = float(p_.duplicate_frac) * std::max(a.w, b.w);
        return std::fabs(a.mean[0] - b.mean[0]) < lim && std::fabs(a.mean[1] - b.mean[1]) < lim;
    });
    for (int i = int(vehicles_.size()) - 1; i >= 0; --i)
        if (twice[size_t(i)]) remove_vehicle(i);
}

void JointParticleFilter::start_transitory(const std::vector<PointMeasurement> &z) {
    if (transitory() || int(vehicles_.size()) >= p_.max_vehicles) return;
    // The strongest measurement that no vehicle explains (not within the gate of an estimate, nor on
    // a vehicle's box: a second region on one vehicle is not a new vehicle).
    int pick = -1;
    for (size_t j = 0; j < z.size() && pick < 0; ++j) {
        bool explained = false;
        for (const auto &v : vehicles_) {
            const float sx = std::max(float(p_.meas_sigma_min_px), float(p_.meas_sigma_x_frac) * v.w);
            const float sy = std::max(float(p_.meas_sigma_min_px), float(p_.meas_sigma_y_frac) * v.w);
            const float dx = (z[j].z.x - v.mean[0]) / sx, dy = (z[j].z.y - v.mean[1]) / sy;
            const bool on_box = std::fabs(z[j].z.x - v.mean[0]) < 0.6f * v.w && z[j].z.y <= v.mean[1] + 0.1f * v.w &&
                                z[j].z.y >= v.mean[1] - v.h;
            if (dx * dx + dy * dy < float(p_.gate_sigma * p_.gate_sigma) || on_box) { explained = true; break; }
        }
        if (!explained) pick = int(j);
    }
    if (pick < 0) return;
    const PointMeasurement &m = z[size_t(pick)];
    candidate_ = Vehicle{};
    candidate_.id = next_id_++;
    candidate_.w = m.box.width;
    candidate_.h = m.box.height;
    candidate_.hits = 1;
    candidate_.support = 1.f;
    candidate_.mean = cv::Vec4f(m.z.x, m.z.y, 0.f, 0.f);
    transitory_frames_ = 0;
    // n_r particles (any: after resampling all weigh the same) get the new vehicle at the measurement.
    const int N = int(vehicles_.size());
    const int nr = std::max(1, int(std::lround(p_.reserve_share * p_.particles)));
    const float sx = std::max(float(p_.meas_sigma_min_px), float(p_.meas_sigma_x_frac) * m.box.width);
    const float sy = std::max(float(p_.meas_sigma_min_px), float(p_.meas_sigma_y_frac) * m.box.width);
    std::normal_distribution<float> n01(0.f, 1.f);
    for (int k = 0; k < nr; ++k) {
        const int s = int((long(k) * p_.particles) / nr);
        float *x = particle(s) + 4 * N;
        x[0] = m.z.x + sx * n01(rng_);
        x[1] = m.z.y + sy * n01(rng_);
        x[2] = float(p_.init_speed_px_s) * n01(rng_);
        x[3] = float(p_.init_speed_px_s) * n01(rng_);
        extended_[size_t(s)] = 1;
    }
}

void JointParticleFilter::step(double dt_s, const std::vector<PointMeasurement> &z_in, cv::Size image, cv::Point2f vp) {
    const float horizon_row = vp.y;
    CV_Assert(dt_s >= 0.0 && image.width > 0 && image.height > 0);
    std::vector<PointMeasurement> z = z_in;
    std::stable_sort(z.begin(), z.end(), [](const PointMeasurement &a, const PointMeasurement &b) {
        return a.strength > b.strength;
    });
    if (int(z.size()) > p_.max_measurements) z.resize(size_t(p_.max_measurements));
    if (!vehicles_.empty() || transitory()) {
        // Perspective: a vehicle's box scales with its row's distance below the horizon.
        auto rescale = [&](Vehicle &v, float y_before) {
            const float d0 = y_before - horizon_row, d1 = v.mean[1] - horizon_row;
            if (d0 > 1.f && d1 > 1.f) { v.w *= d1 / d0; v.h *= d1 / d0; }
        };
        std::vector<float> y_before;
        for (const auto &v : vehicles_) y_before.push_back(v.mean[1]);
        const float cand_y = candidate_.mean[1];
        propagate(dt_s);
        weigh(z, image);
        resample();
        estimate();
        for (size_t i = 0; i < vehicles_.size(); ++i) rescale(vehicles_[i], y_before[i]);
        if (transitory()) rescale(candidate_, cand_y);
        end_transitory(vp, image);
        bookkeeping(z, image, horizon_row);
    }
    start_transitory(z);
}

void JointParticleFilter::report(std::vector<TrackState> &out) const {
    auto one = [&](const Vehicle &v, bool confirmed) {
        TrackState t;
        t.id = v.id;
        t.confirmed = confirmed;
        t.age_frames = v.age;
        t.box = cv::Rect2f(v.mean[0] - 0.5f * v.w, v.mean[1] - v.h, v.w, v.h);
        t.vel_px_s = cv::Point2f(v.mean[2], v.mean[3]);
        t.bottom_sigma_px = v.sigma_y;
        t.confidence = float(v.hits) / float(v.hits + v.missed + 1);
        out.push_back(t);
    };
    for (const auto &v : vehicles_) one(v, true);
    if (transitory()) one(candidate_, false);
}

} // namespace hw
