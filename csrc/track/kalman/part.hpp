// kalman/part.hpp - tracker part "kalman" (the thesis's box tracker): the detector parts every N
// frames, one Kalman filter per vehicle on its bottom corners, ROI search in between.
//
// Per frame (thesis 3.6): predict every vehicle; search the ROI around each prediction for its
// bottom edge and sides; every detect_every_n frames ask the detector parts for a full detection over the road area, let
// a vehicle that its ROI search missed take the detection that overlaps its prediction, and start a
// tentative track on every detection that no track explains. A confirmed vehicle found by neither is
// checked by normalised correlation of its last box before it counts as missed. Tracks are confirmed
// after confirm_hits measurements and deleted after max_misses missed frames (tentative ones after
// tentative_max_misses). Ids are never reused until reset().
//
// Beyond the thesis: the ROI search weighs edges by the prediction (a neighbour's side in the gate
// cannot take the vehicle's), rejects bottom edges that run on beside the vehicle (an overpass
// shadow's edge would capture the track); the prediction adds the image acceleration of constant
// 3D closing speed (perspective_accel) so near, closing vehicles stay inside their gate; a vehicle
// hidden behind a nearer tracked one is not kept alive by correlating the occluder; tracks whose
// width leaves [min_width_ratio, max_width_ratio] expected widths are dropped. The scan and the
// search need no lane model (the detector falls back to the camera's flat-road model).
#pragma once

#include "base/sections.hpp"
#include "cues/verify.hpp"
#include "track/birth_gate.hpp"
#include "track/frame_clock.hpp"
#include "track/kalman/kalman_box.hpp"
#include "track/kalman/roi_search.hpp"
#include "track/kalman/template_check.hpp"
#include "track/tracker.hpp"
#include "track/vehicle_height.hpp"

#include <vector>

namespace hw {

struct KalmanBoxParams {
    int detect_every_n = 3;           // frames between full detections (thesis: 10; 3 measured best)
    double accel_mps2 = 4.0;          // m/s^2; bound A of a vehicle's acceleration relative to the ego
    double ego_accel_px_s2 = 300.0;   // px/s^2; image acceleration from the ego's pitch and yaw motion
    double p_max = 0.1;               // probability of acceleration exactly +-A (bounded-acceleration model)
    double p_zero = 0.5;              // probability of no acceleration
    double meas_sigma_px = 0.7;       // px; measurement noise of a corner, floor
    double meas_sigma_frac = 0.02;    // measurement noise as a fraction of the width, when larger
    double init_speed_mps = 3.0;      // m/s; 1-sigma image speed of a new track, in vehicle widths
    double gate_sigma = 3.0;          // search window half-width in innovation standard deviations
    double min_gate_px = 2.0;         // px; search window half-width, floor
    double side_change_floor_px = 2.0;  // px; floor of the two-threshold rule's largest change
    RoiSearchParams roi;              // bottom_min_frac, max_scale_change
    int confirm_hits = 3;             // M: measurements before a track is confirmed
    int max_misses = 5;               // K: missed frames before a confirmed track is deleted
    int tentative_max_misses = 1;     // missed frames before a tentative track is deleted
    double ncc_min = 0.7;             // normalised correlation that keeps an unfound vehicle
    int ncc_template_px = 24;         // px; templates are scaled to at most this width
    double ncc_min_std_gray = 4.0;    // gray levels; flatter templates are not correlated
    double ncc_search_frac = 0.1;     // shift searched around the prediction, in widths
    double ncc_sigma_scale = 3.0;     // an NCC position is this many times noisier than an edge one
    int max_coast_frames = 15;        // frames a vehicle may live on NCC alone before misses count
    double match_iou = 0.3;           // detection <-> predicted box overlap that is the same vehicle
    double duplicate_iou = 0.5;       // two tracks overlapping this much: the younger is deleted
    double beside_overlap = 0.25;     // a new detection on a tracked vehicle's bottom row whose columns overlap it
    double beside_bottom_tol = 0.2;   // ... by this share of the narrower width is that vehicle (bottoms this many
                                      // widths apart at most): two vehicles at one range cannot overlap in the image
    double min_width_ratio = 0.35;    // track width / expected width at its row, at least
    double max_width_ratio = 2.5;     // ... at most
    double max_dt_s = 1.0;            // s; a longer gap between frames restarts tracking
    double max_width_depth_change = 0.3;   // |width / depth below the horizon of an ROI or template measurement
                                           // against the detections' - 1|, at most (flat road: w = W d / h)
    VehicleHeightParams height;       // section "vehicle_height", taken by share

    void share(const SectionLookup &c) { height = c.get<VehicleHeightParams>("vehicle_height"); }
    void bind(ParamMap &m);
};

class KalmanTracker final : public Tracker {
public:
    // roi: the search around each prediction for the bottom edge and sides (as the shadow detector and its
    // verification find them), and the expected vehicle width at a row.
    KalmanTracker(const KalmanBoxParams &kalman, const RoiSearch &roi);
    void step(const FrameContext &ctx, DetectionStage &detectors, std::vector<TrackState> &tracks, StageTimes &times,
              bool &full_detection) override;
    void reset() override;

private:
    struct Track {
        Track(int id_, const KalmanBox &kf_) : id(id_), kf(kf_) {}
        int id;
        KalmanBox kf;
        int age = 1, hits = 1, misses = 0, coast = 0;
        bool confirmed = false;
        float max_side_change = 0.f;  // two-threshold rule memory (px)
        float confidence = 0.5f;
        VehicleHeight height;         // box height / width, from the detections (a truck keeps its measured one)
        double width_per_depth = 0.0;  // width / (bottom row - horizon) at its detections: W / h on a flat road
        VehicleTemplate appearance;   // last measured box, for the correlation check
        KalmanBox::Vec3 appearance_z = KalmanBox::Vec3::Zero();  // the corners it was cut at
        bool updated = false;         // measured (edges or detection) this frame
    };

    void predict_all(double dt, const cv::Point2f &vp);
    KalmanBox::Vec3 perspective_accel(const Track &t, const cv::Point2f &vp) const;
    bool measure_by_roi(const cv::Mat &gray, Track &t);
    bool measure_by_detection(Track &t, std::vector<Hypothesis> &dets, std::vector<bool> &used);
    bool measure_by_template(const cv::Mat &gray, Track &t);
    bool keeps_width_per_depth(const Track &t, double x1, double y, double x2) const;
    bool occluded(const Track &t) const;
    void start_tracks(const cv::Mat &gray, const std::vector<Hypothesis> &dets, const std::vector<bool> &used);
    void prune(const FrameContext &ctx);
    BirthGateParams birth_gate() const;
    TrackState report(const Track &t) const;

    void apply(Track &t, const KalmanBox::Vec3 &z, float sigma_scale, float quality);
    cv::Rect2f box_of(const KalmanBox::Vec3 &z, double aspect) const;
    cv::Rect2f box_of(const Track &t) const { return box_of(t.kf.measurement(), t.height.aspect); }
    void take_shape(Track &t, const Hypothesis &d) const;
    void note_width_per_depth(Track &t, const cv::Rect2f &b) const;
    KalmanBox::Vec3 sigma_of(const Track &t) const;  // measurement sigmas (x, y, unused)
    double accel_bound(const Track &t) const;

    KalmanBoxParams kalman_;
    RoiSearch roi_;
    std::vector<Track> tracks_;
    int next_id_ = 1;
    int frames_since_detection_ = 0;
    FrameClock clock_;
    float horizon_ = 0.f;             // this frame's horizon row (width per depth of the detections)
    int cols_ = 0;                    // width of the frame being tracked (a box the image side cuts: track/vehicle_height.hpp)
};

} // namespace hw
