// lane_tracker.hpp - lane markings -> lane model, tracked over frames (thesis chapter on lanes).
//
// One frame: row filtering (marking_filter), Hough per half with grouping and rejection
// (hough_lines), vanishing-point consensus and ego/adjacent assignment (lane_assembly).
// Over frames (the thesis names lane tracking as the remedy for markings that are missing or hidden
// by vehicles, but does not build it): every marking is a track with an alpha-beta filter on its x
// at two rows; a measurement joins the track it is within `gate_lanes` lane widths of, so a line
// that jumps implausibly starts a new track instead of moving the old one, and loses the ego
// assignment to the established track; a track that is not measured coasts for up to
// `max_missing_frames` frames, moving with its partner boundary at the tracked lane width when that
// one is still seen (a vehicle hiding one marking while the car drifts); the side of a track is
// re-derived from its slope every frame, so when the car changes lanes the boundary it crosses
// turns from right to left (or back) and the model follows.
#pragma once

#include "core/params.hpp"
#include "core/types.hpp"
#include "geometry/camera.hpp"
#include "lanes/hough_lines.hpp"
#include "lanes/lane_assembly.hpp"
#include "lanes/marking_filter.hpp"

#include <vector>

namespace hw {

struct LaneParams {
    MarkingFilterParams filter;
    HoughLinesParams hough;
    LaneAssemblyParams assembly;
    int max_missing_frames = 15;  // frames a boundary is carried over after it was last measured
    double alpha = 0.6;           // alpha-beta filter: position gain
    double beta = 0.2;            // alpha-beta filter: velocity gain
    double gate_lanes = 0.25;     // lane widths; farthest a measurement may be from its track
    double width_alpha = 0.2;     // smoothing gain of the tracked ego-lane width
    int max_tracks = 8;           // markings tracked at most

    void bind(ParamMap &m) {
        filter.bind(m);
        hough.bind(m);
        assembly.bind(m);
        m.add("max_missing_frames", max_missing_frames, 0, 1000,
              "frames; how long a boundary that is no longer measured is kept by lane tracking; 15 "
              "(0.5 s at 30 fps) bridges dash gaps, worn paint and a vehicle passing over the marking");
        m.add("alpha", alpha, 0.01, 1.0,
              "1; alpha-beta position gain of a tracked boundary; 0.6: line fits are accurate to a pixel, "
              "so follow them closely");
        m.add("beta", beta, 0.0, 1.0,
              "1; alpha-beta velocity gain; 0.2 follows the steady sideways motion of a lane change without lag");
        m.add("gate_lanes", gate_lanes, 0.01, 1.0,
              "lane widths; a measured line farther than this from a tracked boundary (at the bottom row or "
              "mid-band) is a different marking; 0.25 rejects jumps to a neighbouring marking or a vehicle edge");
        m.add("width_alpha", width_alpha, 0.01, 1.0,
              "1; smoothing gain of the tracked ego-lane width used to carry a hidden boundary");
        m.add("max_tracks", max_tracks, 2, 64, "count; markings tracked at most (ego, adjacent and spares)");
    }
};

// Lines of the lane markings in one frame after vanishing-point consensus (outliers dropped).
struct LaneMeasurement {
    std::vector<LaneCandidate> lines;  // weight = supporting rows, observed = true
    cv::Point2f vp{kNaN, kNaN};        // consensus vanishing point, NaN if no two lines agree
};

// known_vp: a vanishing point already known (tracking); null to find it in this frame.
LaneMeasurement measure_lane_lines(const cv::Mat &gray, const LaneParams &p, const CameraParams &cam,
                                   const HorizonPrior &hp, const cv::Point2f *known_vp = nullptr);

// Lane markings of one image alone (no history).
LaneModel detect_lanes(const cv::Mat &gray, const LaneParams &p, const CameraParams &cam);

class LaneTracker {
public:
    LaneTracker(const LaneParams &p, const CameraParams &cam);
    // Measure this frame's markings and update the tracked model in `out`.
    void update(const cv::Mat &gray, LaneModel &out);
    void reset();

private:
    struct Track {
        int id = -1;
        float xb = 0.f, xr = 0.f;  // x at rows yb_ and yr_
        float vb = 0.f, vr = 0.f;  // px per frame
        int hits = 0, missing = 0;
    };
    ImageLine line_of(const Track &t) const;
    void set_line(Track &t, const ImageLine &l) const;
    void associate(const LaneMeasurement &m, const HorizonPrior &hp);

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
};

} // namespace hw
