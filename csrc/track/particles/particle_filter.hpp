// particles/particle_filter.hpp - one SIR particle filter over the joint state of all vehicles, with entries
// and exits managed by the filter itself (paper 000, section III).
//
// State of a particle: (x, y, vx, vy) of each of the N vehicles stacked, x/y the image position of
// the bottom-centre (px), vx/vy its image velocity (px/s). Motion: constant velocity with a random
// acceleration a ~ N(0, sigma_a^2) per axis over each step,
//     x' = x + vx dt + a dt^2 / 2,   vx' = vx + a dt,
// sigma_a^2 = (accel_widths * w)^2 + ego_accel^2 (w the vehicle's image width: near vehicles move
// faster in the image; the ego's pitch and yaw shake moves everything).
// Likelihood of the M measurements z_j (paper eq. 2):
//     p(z | x) = prod_j [ sum_i a_ij p_i(z_j | x_i) + a_u U(z_j) ],
//     a_ij = (1 - a_u) p_i(z_j | x_i) / sum_i p_i(z_j | x_i),
// p_i a bivariate Gaussian around vehicle i (sigma from the vehicle's width), U uniform over the
// image. With those mixing weights the bracket is (1 - a_u) sum_i p_ij^2 / sum_i p_ij + a_u U.
// Eq. 2 alone never penalises a hypothesised vehicle that no measurement supports (a vehicle far
// from every measurement only lowers its own mixing weights), so the transitory period could not end
// in favour of the N-particles as the paper describes. We multiply by a detection term per vehicle,
//     prod_i (1 - p_d + p_d g_i),   g_i = max_j exp(-d_ij^2 / 2)   (d_ij the Mahalanobis distance),
// which is 1 for a vehicle on a measurement and 1 - p_d for one without.
// SIR: propagate, weight, resample (systematic) every step; estimates are particle means.
// Resampling (`resampling`): the paper resamples the joint particle with its joint weight ("joint").
// Then a particle's weight is the product of every vehicle's fit, and each vehicle's slot is kept or
// dropped for how well the *others* fit in the same particle: with N vehicles the spread of the log
// weight grows with N, the effective sample size falls, and a slot whose own evidence is weak (a new,
// wide vehicle: its sigmas are ~25 px, so a pixel of error changes its log weight by little) is
// resampled at random, collapsing onto a few ancestors with whatever velocity they had.
// Measured on overtaking_from_side (tests/test_parallax_tracking.py): over the transitory steps the log
// weight of the other vehicles spread more than the new vehicle's own in ~60 % of them, and the
// effective sample size of the new vehicle's particles was 0.66 of their number under the joint
// weights against 0.93 under its own; the new truck's particles then shrank to a 4 px cloud 20-35 px
// off its measurement with the wrong velocity, and the hypothesis faded, three times in a row.
// "per_vehicle" resamples each vehicle's slot by its own factor of the likelihood (partitioned
// sampling; the independent-partition filter of Vermaak, Godsill and Perez 2005): vehicle i's factor
// in particle s is its contribution to eq. 2 in that particle's context,
//     prod_j [bracket_j(all of s)] / [bracket_j(s without i)] * (1 - p_d + p_d g_i),
// so a measurement that another vehicle of the particle explains still counts for that one (the
// mixture's coupling stays, within the particle the factor was computed in). The candidate's slot and
// the particle's "extended" mark are resampled together by the candidate's factor (1 for a particle
// without it): the competition between the N- and (N+1)-populations is then decided by the new
// vehicle's evidence alone, as the paper intends, instead of by the other vehicles' noise. It
// approximates the joint posterior by a product over vehicles, exact for vehicles that share no
// measurement, which is the case except while two are overlapping in the image.
//
// Entries (transitory period): when a measurement is farther than gate_sigma from every estimate
// and no period runs, n_r = reserve_share * n_s particles get dimension N+1, the new vehicle at the
// measurement (velocity spread init_speed_px_s), and a_u is raised to a_u_transitory so that only
// persistent measurements win. Both populations are propagated and weighted together; the period
// ends when either falls below end_share of the particles: the N+1-particles take over (the vehicle
// is confirmed, with the id it was given at the start) or vanish. A measurement seen in one frame
// only therefore never becomes a confirmed vehicle. A hypothesis that wins is confirmed only if its
// image motion is that of something moving on the road like a vehicle: with the flat-road model, a
// bottom point at (x, y) is at Z = fy h / (y - y_h), X = (x - x_vp) Z / fx, and its image velocity gives
//     dZ/dt = -vy Z^2 / (fy h),   dX/dt = (vx + fx X dZ/dt / Z^2) Z / fx;
// |dX/dt| above max_lateral_mps (a lane change is ~2 m/s) or |dZ/dt| above max_closing_mps means a
// chain of artifacts, not a vehicle.
// Exits: a vehicle whose estimate leaves the image (by roi_margin_px) or rises to the horizon is
// removed; so is one that no measurement has come near for max_missed_frames, or whose running
// share of measured frames falls below min_support (the paper removes vehicles at the border only,
// but a vehicle whose motion stops showing parallax would drift on its last velocity forever, and
// an artifact now and then near it would keep a ghost alive).
// Cost per step: O(n_s * N * (M + 1)) for weighting and O(n_s * N) for propagation and resampling,
// i.e. linear in N for a fixed particle count and quadratic when M grows with N; bounded by
// max_vehicles and max_measurements.
#pragma once

#include "base/params.hpp"
#include "base/types.hpp"
#include "geometry/camera.hpp"

#include <opencv2/core.hpp>

#include <random>
#include <string>
#include <vector>

namespace hw {

struct ParticleParams {
    int particles = 500;               // n_s
    double reserve_share = 0.2;        // n_r / n_s devoted to a hypothesised vehicle
    double end_share = 0.1;            // a population below this share ends the transitory period
    int max_transitory_frames = 15;    // the period is decided by majority after this many frames
    double a_u = 0.1;                  // clutter mixing coefficient, stationary state
    double a_u_transitory = 0.99;      // raised during a transitory period
    double p_detect = 0.8;             // detection probability in the per-vehicle detection term
    double meas_sigma_x_frac = 0.15;   // measurement sigma across, in vehicle widths
    double meas_sigma_y_frac = 0.08;   // measurement sigma of the bottom row, in vehicle widths
    double meas_sigma_min_px = 2.0;    // px; floor of both
    double accel_widths_s2 = 2.0;      // vehicle widths / s^2; random image acceleration of a vehicle
    double ego_accel_px_s2 = 300.0;    // px / s^2; image acceleration from the ego's shake
    double init_speed_px_s = 150.0;    // px / s; velocity spread of a new vehicle
    double gate_sigma = 3.0;           // measurement farther than this (Mahalanobis) from all vehicles: unexplained
    double size_alpha = 0.3;           // smoothing gain of a vehicle's box size from its measurements
    int max_vehicles = 16;             // N at most (cost bound)
    int max_measurements = 16;         // measurements used per frame at most, strongest first (cost bound)
    int max_missed_frames = 12;        // frames without a measurement near it before a vehicle is removed
    double support_alpha = 0.1;        // gain of the running share of frames a vehicle was measured in
    double min_support = 0.3;          // below it (after min_support_age frames) a vehicle is removed
    int min_support_age = 10;          // frames
    double roi_margin_px = 0.0;        // px; an estimate this far outside the image has left
    double duplicate_frac = 0.3;       // two vehicles closer than this many widths: the younger goes
    double max_lateral_mps = 3.5;      // m/s; a hypothesis moving sideways faster on the road is no vehicle
    double border_frac = 0.25;         // vehicle widths; a hypothesis reaching this near the image's side is cut by it
    double max_closing_mps = 70.0;     // m/s; nor one whose range changes faster
    int seed = 1;                      // random seed (runs are reproducible)
    std::string resampling = "per_vehicle";  // "joint" (the paper) | "per_vehicle" (see above)
    double max_dt_s = 1.0;             // s; a longer gap between frames (or time going back) starts the filter again

    void bind(ParamMap &m);
};

// A measurement for the filter: mid-lower point and the region's box.
struct PointMeasurement {
    cv::Point2f z;
    cv::Rect2f box;
    float strength = 0.f;  // orders measurements when there are too many
};

class JointParticleFilter {
public:
    JointParticleFilter(const ParticleParams &p, const CameraParams &cam);

    // One step: propagate over dt, weight with the measurements, resample, estimate, manage entries
    // and exits. image: frame size; vp: the road's vanishing point (estimates up at its row have left).
    void step(double dt_s, const std::vector<PointMeasurement> &z, cv::Size image, cv::Point2f vp);
    // Every vehicle (confirmed) and the hypothesised one (not confirmed), as tracks.
    void report(std::vector<TrackState> &out) const;
    int vehicles() const { return int(vehicles_.size()); }
    bool transitory() const { return candidate_.id > 0; }
    void reset();

private:
    struct Vehicle {
        int id = -1;
        float w = 0.f, h = 0.f;    // box size, px
        int age = 0, missed = 0, hits = 0;
        float support = 1.f;       // running share of frames with a measurement near it
        cv::Vec4f mean;            // particle mean (x, y, vx, vy)
        float sigma_y = 0.f;       // particle spread of y
    };
    int stride() const { return 4 * (int(vehicles_.size()) + 1); }
    float* particle(int s) { return &state_[size_t(s) * size_t(stride())]; }
    void propagate(double dt);
    void weigh(const std::vector<PointMeasurement> &z, cv::Size image);
    void resample();
    // Ancestors by systematic resampling of the n_s log weights starting at logw.
    void systematic(const double *logw, std::vector<int> &ancestor);
    void estimate();
    void end_transitory(cv::Point2f vp, cv::Size image);
    bool plausible(const Vehicle &v, cv::Point2f vp) const;
    void bookkeeping(const std::vector<PointMeasurement> &z, cv::Size image, float horizon_row);
    void remove_vehicle(int i);
    void start_transitory(const std::vector<PointMeasurement> &z);

    ParticleParams p_;
    CameraParams cam_;
    std::vector<Vehicle> vehicles_;
    Vehicle candidate_;                 // id > 0 during a transitory period
    int transitory_frames_ = 0;
    std::vector<float> state_;          // n_s particles x stride floats; slot N is the candidate's
    std::vector<uint8_t> extended_;     // particle carries the candidate
    std::vector<double> logw_;          // joint log weight per particle
    std::vector<double> logf_;          // per_vehicle: log factor of slot i of particle s at [i * n_s + s]
    bool per_vehicle_ = false;
    std::vector<double> cum_;           // systematic(): cumulative weights (kept to save allocations)
    std::mt19937 rng_;
    int next_id_ = 1;
};

} // namespace hw
