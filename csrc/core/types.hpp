// types.hpp - the plain data that flows between the stages of a pipeline.
#pragma once

#include <opencv2/core.hpp>

#include <cmath>
#include <cstdint>
#include <limits>
#include <string>
#include <vector>

namespace hw {

constexpr float kNaN = std::numeric_limits<float>::quiet_NaN();

// One gray frame as it leaves a frame source.
struct Frame {
    cv::Mat gray;        // CV_8UC1, owned
    double t_s = 0.0;    // capture timestamp: monotonic clock for live sources, media time for files
    int64_t number = 0;  // 0-based frame number from the source
    int events = 0;      // HW_EVENT_* bits that happened just before this frame
};

// A lane boundary as an image line through two points (bottom of the road area and towards the VP).
struct LaneBoundary {
    bool valid = false;     // known (measured now or carried over by lane tracking)
    bool observed = false;  // measured in this frame
    cv::Point2f bottom{kNaN, kNaN};
    cv::Point2f top{kNaN, kNaN};

    // x of the line at image row y (NaN when not valid or horizontal).
    float x_at(float y) const {
        if (!valid || top.y == bottom.y) return kNaN;
        return bottom.x + (top.x - bottom.x) * (y - bottom.y) / (top.y - bottom.y);
    }
};

// The road as the lane stage sees it in one frame.
struct LaneModel {
    bool valid = false;  // both ego boundaries known
    LaneBoundary ego_left, ego_right;
    LaneBoundary adj_left, adj_right;  // outer boundaries of the adjacent lanes, where visible
    cv::Point2f vanishing_point{kNaN, kNaN};
    int frames_since_observed = 0;     // frames since both ego boundaries were last measured
    std::vector<cv::Point> road_polygon;  // area the detectors scan; empty = none known

    // Ego lane width in pixels at row y, NaN when unknown.
    float lane_width_px(float y) const { return ego_right.x_at(y) - ego_left.x_at(y); }
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

// The road plane's motion from the previous frame to this one, as a tracker that estimates it reports it.
struct RoadMotion {
    enum class State { kNone, kAccepted, kPredicted };
    State state = State::kNone;
    int coast_frames = 0;
    cv::Matx33d H = cv::Matx33d::eye();  // pixels, previous -> current
};

// Everything one frame produced.
struct FrameOutput {
    int64_t frame_number = 0;
    double t_capture_s = 0.0, t_done_s = 0.0;
    int width = 0, height = 0;
    int events = 0;
    bool full_detection = false;
    std::vector<TrackState> tracks;
    LaneModel lanes;
    float horizon_row = kNaN;
    int lead_id = -1;
    int fcw_level = 0;
    StageTimes times;
    float total_ms = 0.f;
    float image_mean = kNaN, image_stddev = kNaN, image_change = kNaN;  // see capture/image_stats.hpp
    RoadMotion road;
    // the camera's pitch, yaw and height as self-calibration has them, 1-sigma (geometry/self_calibration.hpp)
    float calib_pitch_deg = kNaN, calib_yaw_deg = kNaN, calib_height_m = kNaN;
    float calib_pitch_sigma_deg = kNaN, calib_yaw_sigma_deg = kNaN, calib_height_sigma_m = kNaN;
    int calib_updates = 0;
    bool calib_active = false;
};

} // namespace hw
