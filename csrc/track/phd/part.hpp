// phd/part.hpp - tracker part "phd" (paper 004): the feature points inside each vehicle followed by a GM-PHD
// filter, the vehicle's position from its stable features (eq. 13-15), and its range and velocity
// from a UKF through the pinhole observation (eq. 16-21).
//
// Per frame, for each vehicle:
//   1. Its features of the previous frame (the PHD components' means) are followed by pyramidal LK
//      with the forward-backward check (box_features.hpp). Their median shift and median change of
//      pairwise distance give the vehicle's image motion (shift t, scale s about the features' median c);
//      a followed point more than outlier_px from that motion (the road, the background) is left out.
//   2. PHD prediction with that motion (eq. 6); every birth_every_n frames new corners in the box are
//      candidate births (eq. 7, admitted with probability P_clutter); the followed points and the new
//      corners are the measurement set of the PHD update (eq. 3-5); merging and pruning (eq. 8-11).
//   3. Each feature carries (as its PHD tag) its offset from the vehicle's contact point (bottom centre
//      of the box) in units of the contact's depth below the horizon d = v_c - v_h (= fy h / Z), set when
//      it is born and pulled towards each matched detection. A point H above the road has the tag
//      (X/h, -H/h) at every range, so each stable feature (weight >= stable_weight) gives the contact
//      alone: d = (v - v_h) / (1 + t_y), contact (u - t_x d, v_h + d); no box width enters (tags in box
//      widths put the contact 0.5-1.3 px low for a box 2-7 px too wide, docs/decisions.md). The
//      estimator fuses them: by weight (eq. 13), by inverse covariance determinant (eq. 14) or the
//      heaviest one (eq. 15), each also by (1 + t_y)^2 (a row error is divided by 1 + t_y).
//   4. The UKF (vehicle_ukf.hpp) predicts with constant velocity and updates with that contact point, and
//      with the feature cloud's expansion (s - 1)/dt = -(dZ/dt)/Z, which carries the range rate without
//      the contact row's pixel offset. The expansion's 1-sigma is the pair ratios' spread over the square
//      root of at most expansion_independent_points points: road and background points inside the box
//      expand faster than the vehicle and bias every point alike, which more points do not average out.
//      The horizon row the contact is read against follows the car's pitch through the far scene's
//      vertical motion, the slow part from the lanes (scene_pitch.hpp).
//   5. Every detect_every_n frames it asks the detector parts for a full detection; any detector composes. With
//      detect_lag L > 0 the detection of frame k - L runs on a worker thread (detect/detection_worker.hpp) and is
//      taken at frame k, the frame thread waiting there if it is not done: a fixed L keeps the tracks the same on any
//      machine. The first frame (nothing tracked yet) and compositions with a part that needs the road's motion
//      detect on the frame thread at once. The
//      detections are paired with the vehicles' boxes of the detection's frame in two stages by score (association.hpp:
//      Hungarian on IoU, the confident detections first, the weak ones only for the vehicles left and not hidden
//      by a nearer one: a weak box there is mostly the nearer one's edge); a late
//      detection paired with a vehicle is moved by that vehicle's own image motion since its frame. A paired
//      detection re-measures its vehicle's contact point (UKF update), pulls its width and features' offsets
//      towards the detected box, and counts as a hit (confirmation); an unexplained confident detection starts a
//      vehicle if it stands on the road ahead (road_ahead.hpp). A paired detection whose contact row is farther than detection_gate_sigma from the one the UKF
//      predicts (in sigmas of the row's innovation) is a box that took in something else (the road's shadow
//      under the vehicle, a neighbour): it counts as a hit but neither measures nor re-anchors the vehicle.
//   6. A vehicle ends when the PHD weight inside its box falls under end_weight (eq. 12), when the
//      detector has missed it max_detection_misses times in a row, or when it leaves the image. A confirmed
//      vehicle whose weight falls under end_weight first coasts for up to coast_frames frames: a sudden change
//      of its appearance (it drives into a bridge's shadow) fails every LK feature's forward-backward check
//      at once, while the vehicle moves on as before. While coasting its contact point is the UKF's
//      prediction (constant velocity on the road, eq. 19) and its width follows the predicted range
//      (w Z constant); the corners found in its box each birth_every_n frames are its new features, and
//      once their weight is back over end_weight it is followed by them again. A vehicle whose box a nearer
//      vehicle's box covers (more than coast_max_hidden of it) does not coast: being hidden explains the lost
//      features, and it is gone from view.
// Range, lateral offset and range rate are the UKF's; the geometry stage adds the TTCs.
#pragma once

#include "base/sections.hpp"
#include "geometry/horizon.hpp"
#include "geometry/road_params.hpp"
#include "track/association.hpp"
#include "track/frame_clock.hpp"
#include "track/phd/box_features.hpp"
#include "track/phd/gmphd.hpp"
#include "track/phd/road_ahead.hpp"
#include "track/phd/scene_pitch.hpp"
#include "track/phd/vehicle_ukf.hpp"
#include "track/tracker.hpp"
#include "track/vehicle_height.hpp"

#include <memory>
#include <vector>

namespace hw {

struct PhdTrackerParams {
    int detect_every_n = 3;            // frames between runs of the detector (new vehicles, re-anchoring)
    int detect_lag = 0;                // frames; a detection runs on a worker thread and is taken this much later
                                       // (at most detect_every_n - 1; 0 = on the frame thread, at once)
    std::string estimator = "weights";  // weights (eq. 13) | covariance (eq. 14) | max_weight (eq. 15)
    int birth_every_n = 2;             // frames between searches for new corners (candidate births)
    double outlier_px = 1.5;           // px; a followed point this far from the vehicle's motion is not measured
    double end_weight = 1.5;           // eq. 12: weight inside the box under which a vehicle has ended
    int min_stable = 3;                // stable features needed to measure the contact point
    double min_depth_ratio = 0.6;      // a feature's row below the horizon / the contact's under this: not used for range
    double expansion_sigma_min = 0.002;  // least 1-sigma of the cloud's frame-to-frame scale (UKF rate observation)
    int expansion_independent_points = 4;     // points counted as independent in the expansion's 1-sigma, at most
    double expansion_min_width_px = 40.0;  // px; narrower (far) vehicles: no expansion observation
    double contact_sigma_px = 0.8;     // px; 1-sigma of the features' contact point (UKF R)
    double contact_full_depth = 16.0;  // sum of k^2 over the features at which contact_sigma_px holds (0: always)
    double detection_sigma_px = 2.0;   // px; 1-sigma of a detection's contact point (UKF R)
    double detection_gate_sigma = 6.0;  // sigmas; a paired detection's contact row farther from the vehicle's predicted
                                        // one: a hit, not a measurement (0 = no gate)
    double anchor_gain = 0.5;          // share of a matched detection's box taken into width and offsets
    AssociationParams association;     // detections <-> vehicles: Hungarian on IoU, confident ones first
    double duplicate_iou = 0.5;        // two vehicles overlapping this much: the younger goes
    double nearer_below = 0.5;         // own box heights; a box standing this much lower than a vehicle's, across its
                                       // columns, is a nearer vehicle in front of it: not part of it at birth, and a
                                       // vehicle (almost) inside a confirmed nearer one's box is hidden and goes
                                       // (0 = neither rule)
    int confirm_hits = 2;              // detections before a vehicle is confirmed
    double birth_min_appearance = 0.9;  // a learned detection scoring under this starts no vehicle (it may still
                                        // re-anchor one); others are not affected
    int birth_lanes_beside = 2;        // lanes; a detection farther beside the ego lane (or path) starts no vehicle
    RoadParams road;                   // section "road" (lane width: the birth gate without lanes), taken by share
    int max_detection_misses = 5;      // detector runs in a row that may miss a confirmed vehicle
    int coast_frames = 3;              // frames a confirmed vehicle whose features were lost (eq. 12) is carried by
                                       // its UKF alone before it ends (0 = it ends at once, the paper's rule)
    int coast_min_hits = 6;            // detections (the last run's included) a vehicle needs before it may coast
    double coast_max_hidden = 0.25;    // share of its box a nearer vehicle's box may cover for a vehicle to coast
    bool weak_keeps_hidden = false;    // a weak detection may keep alive a vehicle a nearer one hides (coast_max_hidden)
    double max_dt_s = 1.0;             // s; a longer gap between frames restarts tracking
    BoxFeatureParams features;         // corners and LK (section phd_features)
    GmPhdParams phd;                   // the GM-PHD filter (section gmphd)
    VehicleUkfParams ukf;              // the UKF (section phd_ukf)
    ScenePitchParams pitch;            // the horizon followed through the car's pitch (section phd_pitch)
    VehicleHeightParams height;        // section "vehicle_height", taken by share

    void share(const SectionLookup &c) {  // the road's widths, the vehicle's height
        road = c.get<RoadParams>("road");
        height = c.get<VehicleHeightParams>("vehicle_height");
    }
    void bind(ParamMap &m);
};

class PhdTracker final : public Tracker {
public:
    // horizon: the lanes' horizon row followed over frames (the slow part of the car's pitch).
    PhdTracker(const PhdTrackerParams &p, const CameraParams &camera, const HorizonTracker &horizon);
    void step(const FrameContext &ctx, DetectionStage &detectors, std::vector<TrackState> &tracks, StageTimes &times,
              bool &full_detection) override;
    void reset() override;
    // Self-calibration's camera: the vehicles' range (UKF states rescaled to its height) and the horizon's limits.
    void set_camera(const CameraParams &camera) override;

private:
    struct Vehicle {
        Vehicle(int id_, const GmPhd &phd_) : id(id_), phd(phd_) {}
        int id = 0;
        GmPhd phd;
        std::unique_ptr<VehicleUkf> ukf;
        cv::Point2d contact;           // bottom centre of the box, px
        double width = 0.0;            // box width px
        VehicleHeight height;          // box height / width, from the detections (a truck keeps its measured one)
        cv::Point2d motion{0, 0};      // image shift of the last frame, px
        int age = 1, hits = 1, detection_misses = 0;
        int coast = 0;                 // frames in a row its PHD weight has been under end_weight (coasting)
        double prev_range = 0.0;       // m; the UKF's range before this frame's prediction
        bool confirmed = false;
        int stable = 0;                // stable features this frame
        float confidence = 0.5f;
        cv::Rect2f box() const {
            const double h = height.aspect * width;
            return {float(contact.x - 0.5 * width), float(contact.y - h), float(width), float(h)};
        }
    };

    void follow_features(std::vector<Vehicle> &vs, const cv::Mat &gray, double horizon, double dt);
    void measure(Vehicle &v, const std::vector<cv::Point2f> &prev, const std::vector<cv::Point2f> &cur,
                 const std::vector<uchar> &ok, const cv::Mat &gray, double horizon, double dt);
    bool contact_from_features(const Vehicle &v, double horizon, cv::Point2d &c, double &depth) const;
    static cv::Vec2d tag_of(const cv::Vec2d &m, const cv::Point2d &contact, double horizon);
    // A vehicle's box on the frame a detection was found on (detect_lag): what the detection is compared with.
    struct VehicleAt {
        int id = 0;
        cv::Rect2f box;
        cv::Point2d contact;
        double width = 0.0;
    };
    std::vector<VehicleAt> vehicles_now() const;
    // `then`: the vehicles as they were on the detections' frame (empty: this frame); `lanes`: that frame's.
    void use_detections(const FrameContext &ctx, const LaneModel &lanes, const std::vector<Hypothesis> &dets,
                        double horizon, const std::vector<VehicleAt> &then);
    bool start_vehicle(const cv::Mat &gray, const Hypothesis &d, double horizon);  // false: its foot is off the road
    void prune(const FrameContext &ctx, double horizon);
    bool hidden(const Vehicle &v) const;  // a nearer vehicle's box covers more than coast_max_hidden of its box
    TrackState report(const Vehicle &v) const;

    PhdTrackerParams p_;
    CameraParams cam_;
    HorizonTracker horizon_;
    PointFlow flow_;
    ScenePitch pitch_;
    std::vector<Vehicle> vehicles_;
    int next_id_ = 1;
    int64_t frame_ = 0;
    // the detection running on the worker (detect_lag): the frame it is taken on (-1: none), that frame's lanes and
    // vehicles
    int64_t lagged_due_ = -1;
    LaneModel lagged_lanes_;
    std::vector<VehicleAt> lagged_vehicles_;
    FrameClock clock_;
};

} // namespace hw
