// lane_tracker.hpp - lane markings -> lane model, tracked over frames (thesis chapter on lanes).
//
// One frame: row filtering (marking_filter), Hough per half with grouping and rejection
// (hough_lines), vanishing-point consensus and ego/adjacent assignment (lane_assembly).
// Over frames (the thesis names lane tracking as the remedy for markings that are missing or hidden
// by vehicles, but does not build it): every marking is a track with a Kalman filter on its x
// at two rows; a measurement joins the track it is within `gate_lanes` lane widths of, so a line
// that jumps implausibly starts a new track instead of moving the old one, and loses the ego
// assignment to the established track; a track that is not measured coasts for up to
// `max_missing_frames` frames, moving with its partner boundary at the tracked lane width when that
// one is still seen (a vehicle hiding one marking while the car drifts); the side of a track is
// re-derived from its slope every frame, so when the car changes lanes the boundary it crosses
// turns from right to left (or back) and the model follows.
#pragma once

#include "base/params.hpp"
#include "base/types.hpp"
#include "geometry/camera.hpp"
#include "lanes/dark_markings.hpp"
#include "lanes/dot_markings.hpp"
#include "lanes/hough_lines.hpp"
#include "lanes/lane_assembly.hpp"
#include "lanes/lane_curve.hpp"
#include "lanes/lane_evidence.hpp"
#include "lanes/marking_filter.hpp"

#include <vector>

namespace hw {

struct LaneParams {
    MarkingFilterParams filter;
    HoughLinesParams hough;
    LaneAssemblyParams assembly;
    LaneCurveParams curve;
    LaneEvidenceParams evidence;
    DotMarkingParams dots;
    DarkLineParams dark;
    int max_missing_frames = 15;         // frames a boundary is carried after it was last measured
    double marking_sigma_px = 1.0;       // px; noise of one marking point (measurement model)
    double process_accel_frac = 0.0015;  // fraction of width per frame^2; how fast a boundary may move
    double gate_lanes = 0.25;            // lane widths; farthest a measurement may be from its track
    double width_alpha = 0.2;            // smoothing gain of the tracked ego-lane width
    int max_tracks = 8;                  // markings tracked at most
    bool reject_in_vehicles = false;     // marking points inside last frame's confirmed vehicle boxes dropped
    double vehicle_mask_frac = 0.75;     // of a box's height, from its top: the part whose points are dropped

    void bind(ParamMap &m) {
        filter.bind(m);
        hough.bind(m);
        assembly.bind(m);
        curve.bind(m);
        evidence.bind(m);
        dots.bind(m);
        dark.bind(m);
        m.add("max_missing_frames", max_missing_frames, 0, 1000,
              "frames; how long a boundary that is no longer measured is kept by lane tracking; 15 "
              "(0.5 s at 30 fps) bridges dash gaps, worn paint and a vehicle passing over the marking");
        m.add("marking_sigma_px", marking_sigma_px, 0.05, 50.0,
              "px; noise of one marking-centre point; a measured line's variance at a row follows from its "
              "least-squares fit (a long marking counts fully, a line through one short far dash hardly "
              "moves the boundary at the bottom of the image)");
        m.add("process_accel_frac", process_accel_frac, 0.0, 0.1,
              "fraction of the image width per frame^2; white-acceleration noise of a boundary's column "
              "(Kalman process noise); 0.0015 (1 px/frame^2 at 640) follows a lane change at 1 m/s and pitch shake");
        m.add("gate_lanes", gate_lanes, 0.01, 1.0,
              "lane widths; a measured line farther than this from a tracked boundary (at the bottom row or "
              "mid-band) is a different marking; 0.25 rejects jumps to a neighbouring marking or a vehicle edge");
        m.add("width_alpha", width_alpha, 0.01, 1.0,
              "1; smoothing gain of the tracked ego-lane width used to carry a hidden boundary");
        m.add("max_tracks", max_tracks, 2, 64, "count; markings tracked at most (ego, adjacent and spares)");
        m.add("reject_in_vehicles", reject_in_vehicles,
              "drop the marking points inside the upper vehicle_mask_frac of the vehicles confirmed in the previous "
              "frame (lights, plates, trim are not lane lines; docs/lanes.md)");
        m.add("vehicle_mask_frac", vehicle_mask_frac, 0.05, 1.0,
              "fraction of a vehicle box's height, from its top, inside which reject_in_vehicles drops marking "
              "points; 0.75 keeps the wheels' quarter (docs/lanes.md)");
    }
};

// Lines of the lane markings in one frame after vanishing-point consensus (outliers dropped).
struct LaneMeasurement {
    std::vector<LaneCandidate> lines;  // weight = supporting rows, observed = true
    cv::Point2f vp{kNaN, kNaN};        // consensus vanishing point, NaN if no two lines agree
    std::vector<MarkingPoint> points;  // the frame's marking centres (the curve fit uses them)
};

// One frame's lines (lane_detection.cpp): the wide search and consensus find the vanishing point,
// the narrow search around it every marking. known_vp: a vanishing point already known (tracking),
// which skips the wide search unless the narrow one finds fewer than two lines; null: this frame's.
// vehicles: image boxes whose marking points are dropped (null or empty: none). tracking: the frame is one of a
// video (Botts' dots are looked for only with dots_in_tracking).
LaneMeasurement measure_lane_lines(const cv::Mat &gray, const LaneParams &p, const CameraParams &cam,
                                   const HorizonPrior &hp, const cv::Point2f *known_vp = nullptr,
                                   const std::vector<cv::Rect2f> *vehicles = nullptr, bool tracking = false);

// Lane markings of one image alone (no history).
LaneModel detect_lanes(const cv::Mat &gray, const LaneParams &p, const CameraParams &cam);

class LaneTracker {
public:
    LaneTracker(const LaneParams &p, const CameraParams &cam);
    // Measure this frame's markings and update the tracked model in `out`. vehicles: the tracker's
    // output of the previous frame (the confirmed ones hide the road; reject_in_vehicles), may be empty.
    void update(const cv::Mat &gray, LaneModel &out, const std::vector<TrackState> &vehicles = {});
    void reset();
    // Where the vanishing point is searched: the horizon of `cam` (pitch, yaw) +- tol_deg. Self-calibration sets
    // it every frame: the whole range the pitch may still take while it searches, its estimate +- the lanes'
    // horizon_tolerance_deg once it has converged. The constructor's window: the configured camera's. Without
    // tracks (after reset()) the rows the tracks keep their columns at follow the window's horizon.
    void set_search_window(const CameraParams &cam, double tol_deg);

private:
    // Constant-velocity Kalman filter of a boundary's column on one row (px, px per frame).
    struct RowFilter {
        float x = 0.f, v = 0.f;
        float p00 = 0.f, p01 = 0.f, p11 = 0.f;  // covariance of (x, v)
        void init(float z, float r, float v_var);
        void predict(float q);                  // q: acceleration sigma, px per frame^2
        void update(float z, float r);          // r: measurement variance, px^2
    };
    struct Track {
        int id = -1;
        RowFilter b, r;  // columns at rows yb_ and yr_
        int hits = 0, missing = 0;
        float support = kNaN;  // smoothed share of range bins with paint on it (lane_evidence.hpp)
    };
    ImageLine line_of(const Track &t) const;
    void set_line(Track &t, const ImageLine &l) const;
    HorizonPrior search_prior() const;
    void set_rows();  // yb_, yr_ from the search window's horizon
    void associate(const LaneMeasurement &m, const HorizonPrior &hp);
    std::vector<LaneCandidate> candidates() const;
    void carry_ego_width(std::vector<LaneCandidate> &cands, LaneAssignment &a, cv::Point2f vp);
    void update_support(const LaneMeasurement &m, const std::vector<TrackState> &vehicles, float y_h,
                        const ScanBand &band, LaneModel &out);

    LaneParams p_;
    CameraParams cam_;
    HorizonPrior prior_;
    float yb_ = 0.f, yr_ = 0.f;  // rows at which tracks keep their x
    std::vector<Track> tracks_;
    int next_id_ = 0;
    int ego_left_id_ = -1, ego_right_id_ = -1;
    float width_k_ = kNaN;  // tracked ego width as a slope difference
    int width_age_ = 0;     // frames since the width was last measured
    cv::Point2f vp_{kNaN, kNaN};
    int frames_since_observed_ = 0;
    LaneCurveState curve_;
    std::vector<cv::Rect2f> hidden_;  // boxes of this frame's update whose marking points are dropped
};

} // namespace hw
