// types.hpp - the plain data that flows between the stages of a pipeline.
#pragma once

#include <opencv2/core.hpp>

#include <cmath>
#include <cstdint>
#include <limits>
#include <string>
#include <vector>

namespace hw {

// Intersection over union of two boxes (0 when they do not overlap or both are empty).
inline float box_iou(const cv::Rect2f &a, const cv::Rect2f &b) {
    const float inter = (a & b).area();
    const float uni = a.area() + b.area() - inter;
    return uni > 0.f ? inter / uni : 0.f;
}

constexpr float kNaN = std::numeric_limits<float>::quiet_NaN();

// One gray frame as it leaves a frame source.
struct Frame {
    cv::Mat gray;        // CV_8UC1, owned
    double t_s = 0.0;    // capture timestamp: monotonic clock for live sources, media time for files
    int64_t number = 0;  // 0-based frame number from the source
    int events = 0;      // FrameEvent bits that happened just before this frame
};

// Health events of the frame source, as bits of Frame::events and FrameOutput::events (the ABI's
// HW_EVENT_* carry the same values; abi.cpp checks that at compile time).
enum FrameEvent : int {
    kEventDecodeError = 1,   // a frame could not be decoded and was skipped
    kEventSourceLost = 2,    // a live device stopped delivering
    kEventReconnected = 4,   // a live device came back
    kEventSizeChanged = 16,  // a frame of another size than the first one was skipped
    kEventConcealed = 32,    // this frame was decoded with errors the decoder concealed (damaged regions filled in)
};

// The car's own motion from the vehicle bus.
struct EgoMotion {
    double speed_mps = NAN;      // NaN = not available
    double yaw_rate_rps = NAN;   // positive turning left; NaN = not available
};

// A lane boundary as an image line through two points (bottom of the road area and towards the VP).
struct LaneBoundary {
    bool valid = false;     // known (measured now or carried over by lane tracking)
    bool observed = false;  // measured in this frame
    cv::Point2f bottom{kNaN, kNaN};
    cv::Point2f top{kNaN, kNaN};
    // Bend (lanes/lane_curve.hpp): the boundary is x = a + b d + bend d^2 + curve / d, d = y - curve_row,
    // through bottom and top; curve (road curvature) and bend (image second order) 0 = straight.
    float curve = 0.f;        // px^2
    float bend = 0.f;         // 1/px
    float curve_row = kNaN;   // px; horizon row of the curve term

    // x of the chord from bottom to top at image row y (NaN when not valid or horizontal).
    float x_at(float y) const {
        if (!valid || top.y == bottom.y) return kNaN;
        return bottom.x + (top.x - bottom.x) * (y - bottom.y) / (top.y - bottom.y);
    }
    // x of the curved boundary at row y (also beyond top, extrapolated): the chord plus curve times
    // (1/d minus its chord) plus bend times (d^2 minus its chord).
    float curve_x(float y) const {
        const float x = x_at(y);
        if ((curve == 0.f && bend == 0.f) || !std::isfinite(curve_row) || y <= curve_row) return x;
        const float db = bottom.y - curve_row, dt = top.y - curve_row, d = y - curve_row;
        const float s = (y - bottom.y) / (top.y - bottom.y);
        return x + curve * (1.f / d - (1.f / db + (1.f / dt - 1.f / db) * s)) +
               bend * (d * d - (db * db + (dt * dt - db * db) * s));
    }
};

// The road as the lane stage sees it in one frame.
struct LaneModel {
    bool valid = false;  // both ego boundaries known
    bool certain = false;  // valid (implies it), and both ego boundaries have paint along the road (lanes/lane_evidence.hpp)
    LaneBoundary ego_left, ego_right;
    LaneBoundary adj_left, adj_right;  // outer boundaries of the adjacent lanes, where visible
    LaneBoundary out_left, out_right;  // one lane further out: outer boundaries of the lanes beyond, where visible
    cv::Point2f vanishing_point{kNaN, kNaN};
    int frames_since_observed = 0;     // frames since both ego boundaries were last measured
    float far_row = kNaN;   // px; row the reported boundaries reach (curve extrapolated), NaN = their top
    float width_m = kNaN;   // ego-lane width at the bottom row (flat road), NaN unless both ego boundaries
    float offset_m = kNaN;  // the car's centre right of the ego lane's centre, m, NaN unless both
    std::vector<cv::Point> road_polygon;  // area the detectors scan; empty = none known

    // Ego lane width in pixels at row y, NaN when unknown.
    float lane_width_px(float y) const { return ego_right.x_at(y) - ego_left.x_at(y); }
    // Whether a point (u, y) lies on the ego lane or within `lanes_beside` ego-lane widths of it; true when the
    // model does not say (not valid, or no width at that row).
    bool near_ego_lane(float u, float y, int lanes_beside) const {
        const float l = ego_left.x_at(y), r = ego_right.x_at(y);
        if (!valid || !std::isfinite(l) || !std::isfinite(r) || !(r > l)) return true;
        const float w = r - l;
        return u >= l - float(lanes_beside) * w && u <= r + float(lanes_beside) * w;
    }
};

// A vehicle as a tracker reports it.
struct TrackState {
    int id = -1;
    bool confirmed = false;
    int age_frames = 0;
    cv::Rect2f box;                  // left, top, width, height in px
    float confidence = 0.f;          // 0..1
    cv::Point2f vel_px_s{kNaN, kNaN}; // image velocity of the bottom centre
    float bottom_sigma_px = kNaN;    // 1-sigma uncertainty of the bottom row (for range uncertainty)
    // Filled by the geometry stage (NaN until then).
    float range_m = kNaN, range_sigma_m = kNaN, lateral_m = kNaN, range_rate_mps = kNaN;
    float range_accel_mps2 = kNaN;   // relative acceleration d2(range)/dt2
    // A tracker that estimates the range rate itself (phd's UKF) gives its estimate in range_rate_mps and its
    // 1-sigma here; the geometry stage keeps the rate only once this is below 2 m/s (track_kinematics.hpp).
    float range_rate_sigma_mps = kNaN;
    float ttc_s = kNaN, ttc_scale_s = kNaN;
    int lane_index = -1000;          // -1000 unknown
    int in_path = -1;                // -1 unknown
};

// Per-stage wall time of one frame, in the order the stages ran.
struct StageTimes {
    std::vector<std::pair<std::string, float>> items;
    void add(const std::string &name, float ms) {
        for (auto &it : items)
            if (it.first == name) { it.second += ms; return; }
        items.emplace_back(name, ms);
    }
};

// The road plane's motion from the previous frame to this one, as the road-motion stage reports it.
struct RoadMotion {
    enum class State { kNone, kAccepted, kPredicted };
    State state = State::kNone;
    int coast_frames = 0;
    cv::Matx33d H = cv::Matx33d::eye();  // pixels, previous -> current
    // This frame's correspondences fitted once more with the road plane's tilt free (homography.fit_tilt,
    // geometry/road_motion_fit.hpp), around the mounting the stage assumed: whether that fit explained them,
    // the tilt e (rad: the mounting's true pitch minus the assumed one, down positive) and the travel (m,
    // scaled by the assumed height: true travel * assumed height / true height). Self-calibration's pitch
    // and height from the road's motion; NaN when not fitted.
    bool tilt_ok = false;
    double tilt_rad = kNaN, tilt_travel_m = kNaN;
    // How well H aligns the road (homography.measure_residual, RoadMotionStage::road_residual): mean |difference|
    // in gray levels over the road pixels, outside this frame's detections and the bonnet, between this frame and
    // the previous one warped with H with their smooth brightness change taken out; the same unwarped; and warped
    // with the brightness change left in. NaN when not measured or without an estimate.
    float residual = kNaN, residual_unaligned = kNaN, residual_raw = kNaN;
};

// What the road-motion stage (road/road_motion_stage.hpp) hands the parts that need it in one frame:
// the filtered homography and the road band it aligned, at the pyramid level the parallax detector uses.
struct RoadMotionFrame {
    RoadMotion motion;          // state kNone: no estimate this frame
    cv::Point2f vp{kNaN, kNaN}; // the road's vanishing point: the lane model's, else the camera's horizon and yaw
    int band_top = 0;           // px; first image row of the road band
    int level = 0;              // pyramid level of the bands below (0 = full resolution)
    cv::Mat band;               // this frame's road band (rows band_top .. height-1) at that level
    cv::Mat prev_band;          // the previous frame's, same size; empty when there is none
    int hood_row = 0;           // px; first image row of the car's bonnet (height: none)
    bool valid() const { return motion.state != RoadMotion::State::kNone; }
};

// Everything one frame produced.
// One vehicle of the detection stage: its box and score (0..1).
struct DetectedBox {
    cv::Rect2f box;
    float score = 0.f;
};

struct FrameOutput {
    int64_t frame_number = 0;
    double t_capture_s = 0.0, t_done_s = 0.0;
    int width = 0, height = 0;
    int events = 0;
    bool full_detection = false;
    std::vector<TrackState> tracks;
    std::vector<DetectedBox> detections;  // the detection stage's vehicles the tracker took this frame, strongest first
    int64_t detections_frame = -1;        // the frame they were found on (earlier than this one with phd.detect_lag)
    LaneModel lanes;
    float horizon_row = kNaN;
    int lead_id = -1;
    StageTimes times;
    float total_ms = 0.f;
    float image_mean = kNaN, image_stddev = kNaN, image_change = kNaN;  // see capture/image_stats.hpp
    RoadMotion road;
    // the camera's pitch, yaw and height as self-calibration has them, 1-sigma (geometry/self_calibration.hpp)
    float calib_pitch_deg = kNaN, calib_yaw_deg = kNaN, calib_height_m = kNaN;
    float calib_pitch_sigma_deg = kNaN, calib_yaw_sigma_deg = kNaN, calib_height_sigma_m = kNaN;
    int calib_updates = 0;
    bool calib_active = false;
    int calib_state = 0;  // CalibrationState (0 off, 1 learning, 2 converged, 3 at a limit)
};

} // namespace hw
