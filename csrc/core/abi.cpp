// abi.cpp - the door: implements headway.h. Every entry point runs inside guard(), which turns any
// exception into a status code and a per-thread message, so nothing from C++ reaches the caller.
#include "include/headway.h"

#include "capture/push_source.hpp"
#include "core/config.hpp"
#include "base/errors.hpp"
#include "core/pipeline.hpp"
#include "core/realtime_loop.hpp"
#include "base/stopwatch.hpp"

#include <opencv2/core.hpp>
#include <opencv2/core/utils/logger.hpp>

#include <algorithm>
#include <cstring>
#include <memory>
#include <mutex>
#include <string>

struct hw_pipeline {
    hw::Config config;
    std::unique_ptr<hw::Pipeline> pipeline;
    std::unique_ptr<hw::ResultQueue<hw::FrameOutput>> results;
    std::unique_ptr<hw::RealtimeLoop> loop;  // set while started (kept after stop for health)
    std::mutex mu;                           // serialises start/stop/process against each other
    int64_t offline_frames = 0;              // frame numbers for process()
};

namespace {

thread_local std::string g_last_error;

int fail(int code, const std::string &msg) {
    g_last_error = msg;
    return code;
}

template <class Fn> int guard(Fn &&fn) {
    try {
        g_last_error.clear();
        return fn();
    } catch (const hw::ConfigError &e) {
        return fail(HW_ERR_CONFIG, e.what());
    } catch (const hw::SourceError &e) {
        return fail(HW_ERR_SOURCE, e.what());
    } catch (const hw::StateError &e) {
        return fail(HW_ERR_STATE, e.what());
    } catch (const std::invalid_argument &e) {
        return fail(HW_ERR_INVALID_ARGUMENT, e.what());
    } catch (const cv::Exception &e) {
        return fail(HW_ERR_INTERNAL, std::string("OpenCV: ") + e.what());
    } catch (const std::exception &e) {
        return fail(HW_ERR_INTERNAL, e.what());
    } catch (...) {
        return fail(HW_ERR_INTERNAL, "unknown exception in the core");
    }
}

void require(const void *p, const char *what) {
    if (!p) throw std::invalid_argument(std::string(what) + " is NULL");
}

static_assert(HW_EVENT_DECODE_ERROR == hw::kEventDecodeError && HW_EVENT_SOURCE_LOST == hw::kEventSourceLost &&
                  HW_EVENT_RECONNECTED == hw::kEventReconnected && HW_EVENT_SIZE_CHANGED == hw::kEventSizeChanged &&
                  HW_EVENT_CONCEALED == hw::kEventConcealed,
              "hw::FrameEvent bits must equal the ABI's HW_EVENT_* (events are copied as they are)");

int source_state_code(hw::SourceState s) {
    switch (s) {
    case hw::SourceState::kIdle: return HW_SOURCE_IDLE;
    case hw::SourceState::kRunning: return HW_SOURCE_RUNNING;
    case hw::SourceState::kReconnecting: return HW_SOURCE_RECONNECTING;
    case hw::SourceState::kEnded: return HW_SOURCE_ENDED;
    case hw::SourceState::kFailed: return HW_SOURCE_FAILED;
    }
    return HW_SOURCE_FAILED;
}

void fill_health(const hw::LoopHealth &l, hw_health &h) {
    h.running = l.running ? 1 : 0;
    h.source_state = source_state_code(l.source_state);
    h.frames_captured = l.frames_captured;
    h.frames_processed = l.frames_processed;
    h.results_dropped = l.results_dropped;
    h.frames_pushed_dropped = l.frames_pushed_dropped;
    h.decode_errors = l.decode_errors;
    h.source_losses = l.source_losses;
    h.reconnects = l.reconnects;
    h.last_frame_t_s = l.last_frame_t_s;
    h.last_progress_s = l.last_progress_s;
    h.last_alive_s = l.last_alive_s;
    h.last_total_ms = l.last_total_ms;
    h.queue_depth = l.queue_depth;
    h.queue_capacity = l.queue_capacity;
}

void copy_name(char (&dst)[HW_STAGE_NAME_LEN], const std::string &src) {
    std::strncpy(dst, src.c_str(), HW_STAGE_NAME_LEN - 1);
    dst[HW_STAGE_NAME_LEN - 1] = '\0';
}

void fill_stages(const hw::StageTimes &times, hw_stage_time (&out)[HW_MAX_STAGES], int32_t &n) {
    n = int32_t(std::min<size_t>(times.items.size(), HW_MAX_STAGES));
    for (int i = 0; i < n; ++i) {
        copy_name(out[i].name, times.items[size_t(i)].first);
        out[i].ms = times.items[size_t(i)].second;
    }
}

hw_box box_of(const hw::DetectedBox &d) {
    return hw_box{d.box.x, d.box.y, d.box.x + d.box.width, d.box.y + d.box.height, d.score};
}

void fill_result(const hw::FrameOutput &o, hw_frame_result *r) {
    std::memset(r, 0, sizeof(*r));
    r->frame_number = o.frame_number;
    r->t_capture_s = o.t_capture_s;
    r->t_done_s = o.t_done_s;
    r->width = o.width;
    r->height = o.height;
    r->events = o.events;
    r->full_detection = o.full_detection ? 1 : 0;
    r->n_tracks = int32_t(std::min<size_t>(o.tracks.size(), HW_MAX_TRACKS));
    for (int i = 0; i < r->n_tracks; ++i) {
        const auto &t = o.tracks[i];
        hw_track &d = r->tracks[i];
        d.id = t.id;
        d.confirmed = t.confirmed ? 1 : 0;
        d.age_frames = t.age_frames;
        d.left = t.box.x;
        d.top = t.box.y;
        d.right = t.box.x + t.box.width;
        d.bottom = t.box.y + t.box.height;
        d.confidence = t.confidence;
        d.vx_px_s = t.vel_px_s.x;
        d.vy_px_s = t.vel_px_s.y;
        d.range_m = t.range_m;
        d.range_sigma_m = t.range_sigma_m;
        d.lateral_m = t.lateral_m;
        d.range_rate_mps = t.range_rate_mps;
        d.range_accel_mps2 = t.range_accel_mps2;
        d.ttc_s = t.ttc_s;
        d.ttc_scale_s = t.ttc_scale_s;
        d.lane_index = t.lane_index;
        d.in_path = t.in_path;
    }
    r->detections_frame = o.full_detection ? o.detections_frame : -1;
    r->n_detections = int32_t(std::min<size_t>(o.detections.size(), HW_MAX_TRACKS));
    for (int i = 0; i < r->n_detections; ++i) {
        r->detections[i] = box_of(o.detections[size_t(i)]);
    }
    int n = 0;
    auto add_lane = [&](const hw::LaneBoundary &b, int position) {
        if (!b.valid || n >= HW_MAX_LANES) return;
        hw_lane &l = r->lanes[n++];
        l = hw_lane{b.bottom.x, b.bottom.y, b.top.x, b.top.y, position, b.observed ? 1 : 0, 0, {}, {}};
        hw::sample_boundary(b, o.lanes.far_row, HW_LANE_POINTS, l.px, l.py);
        l.n_points = HW_LANE_POINTS;
    };
    add_lane(o.lanes.out_left, -3);
    add_lane(o.lanes.adj_left, -2);
    add_lane(o.lanes.ego_left, -1);
    add_lane(o.lanes.ego_right, +1);
    add_lane(o.lanes.adj_right, +2);
    add_lane(o.lanes.out_right, +3);
    r->n_lanes = n;
    r->vanishing_x = o.lanes.vanishing_point.x;
    r->vanishing_y = o.lanes.vanishing_point.y;
    r->lane_width_m = o.lanes.width_m;
    r->lane_offset_m = o.lanes.offset_m;
    r->lanes_certain = o.lanes.certain ? 1 : 0;
    r->horizon_row = o.horizon_row;
    r->lead_id = o.lead_id;
    fill_stages(o.times, r->stages, r->n_stages);
    r->total_ms = o.total_ms;
    r->image_mean = o.image_mean;
    r->image_stddev = o.image_stddev;
    r->image_change = o.image_change;
    r->road_motion = o.road.state == hw::RoadMotion::State::kAccepted    ? HW_ROAD_ACCEPTED
                     : o.road.state == hw::RoadMotion::State::kPredicted ? HW_ROAD_PREDICTED
                                                                          : HW_ROAD_NONE;
    r->road_coast_frames = o.road.coast_frames;
    for (int i = 0; i < 9; ++i)
        r->road_homography[i] = r->road_motion == HW_ROAD_NONE ? NAN : float(o.road.H.val[i]);
    r->road_residual = o.road.residual;
    r->road_residual_unaligned = o.road.residual_unaligned;
    r->road_residual_raw = o.road.residual_raw;
    r->calib_pitch_deg = o.calib_pitch_deg;
    r->calib_yaw_deg = o.calib_yaw_deg;
    r->calib_height_m = o.calib_height_m;
    r->calib_pitch_sigma_deg = o.calib_pitch_sigma_deg;
    r->calib_yaw_sigma_deg = o.calib_yaw_sigma_deg;
    r->calib_height_sigma_m = o.calib_height_sigma_m;
    r->calib_updates = o.calib_updates;
    r->calib_active = o.calib_active ? 1 : 0;
    r->calib_state = o.calib_state;
}

cv::Mat wrap_gray(const uint8_t *gray, int32_t width, int32_t height, int32_t stride) {
    require(gray, "frame data");
    if (width <= 0 || height <= 0) throw std::invalid_argument("frame size must be positive");
    if (stride < width) throw std::invalid_argument("stride is smaller than the width");
    return cv::Mat(height, width, CV_8UC1, const_cast<uint8_t *>(gray), size_t(stride));
}

void require_stopped(hw_pipeline *p, const char *what) {
    if (p->loop && p->loop->running())
        throw hw::StateError(std::string(what) + " is not allowed while the real-time loop runs; stop it first");
}

} // namespace

extern "C" {

int hw_abi_version(void) { return HW_ABI_VERSION; }

const char *hw_error_message(int code) {
    switch (code) {
    case HW_OK: return "ok";
    case HW_ERR_INVALID_ARGUMENT: return "invalid argument";
    case HW_ERR_CONFIG: return "invalid configuration";
    case HW_ERR_SOURCE: return "frame source cannot be opened";
    case HW_ERR_STATE: return "not allowed in this state";
    case HW_ERR_TIMEOUT: return "timed out";
    case HW_ERR_END_OF_STREAM: return "end of stream";
    case HW_ERR_INTERNAL: return "internal error";
    default: return "unknown status code";
    }
}

const char *hw_last_error(void) { return g_last_error.c_str(); }

double hw_monotonic_s(void) { return hw::monotonic_s(); }

int hw_pipeline_create(const char *config_json, hw_pipeline **out) {
    return guard([&] {
        require(out, "out");
        *out = nullptr;
        // OpenCV's own warnings (a camera index it cannot open, ...) would repeat what our error
        // messages already say, on stderr of a service; keep only its errors.
        cv::utils::logging::setLogLevel(cv::utils::logging::LOG_LEVEL_ERROR);
        auto p = std::make_unique<hw_pipeline>();
        p->config = hw::Config::from_json(config_json ? config_json : "");
        p->pipeline = std::make_unique<hw::Pipeline>(p->config);
        p->results = std::make_unique<hw::ResultQueue<hw::FrameOutput>>(p->config.pipeline.queue_capacity);
        *out = p.release();
        return HW_OK;
    });
}

void hw_pipeline_destroy(hw_pipeline *p) {
    guard([&] {
        if (p) {
            if (p->loop) p->loop->stop();
            delete p;
        }
        return HW_OK;
    });
}

int hw_pipeline_config(hw_pipeline *p, char *buf, int32_t buf_len, int32_t *needed) {
    return guard([&] {
        require(needed, "needed");
        nlohmann::json j;
        if (p) j = p->config.to_json();
        else {  // no pipeline: describe every key with its default, the keys that moved, the presets (and
                // which is Headway's default), the detectors
            j = hw::Config().describe();
            j["moved_keys"] = hw::Config::moved_keys();
            j["presets"] = hw::describe_presets();
            j["default_preset"] = hw::default_preset();
            j["detectors"] = hw::describe_detectors();
            j["removed_presets"] = hw::describe_removed_presets();
        }
        const std::string s = j.dump();
        *needed = int32_t(s.size() + 1);
        if (!buf || buf_len < *needed) throw std::invalid_argument("buffer too small for the configuration");
        std::memcpy(buf, s.c_str(), s.size() + 1);
        return HW_OK;
    });
}

int hw_pipeline_process(hw_pipeline *p, const uint8_t *gray, int32_t width, int32_t height, int32_t stride,
                        double t_s, hw_frame_result *out) {
    return guard([&] {
        require(p, "pipeline");
        require(out, "out");
        std::lock_guard<std::mutex> lock(p->mu);
        require_stopped(p, "process()");
        hw::Frame f;
        f.gray = wrap_gray(gray, width, height, stride);
        f.t_s = t_s;
        f.number = p->offline_frames++;
        fill_result(p->pipeline->process(f), out);
        return HW_OK;
    });
}

int hw_pipeline_detect(hw_pipeline *p, const char *detector, const uint8_t *gray, int32_t width, int32_t height,
                       int32_t stride, hw_box *out, int32_t cap, hw_detect_info *info) {
    return guard([&] {
        require(p, "pipeline");
        require(info, "info");
        if (cap < 0) throw std::invalid_argument("cap must not be negative");
        if (cap > 0) require(out, "out");
        std::lock_guard<std::mutex> lock(p->mu);
        require_stopped(p, "detect()");
        const hw::ImageDetections d = p->pipeline->detect_image(detector ? detector : "", wrap_gray(gray, width, height, stride));
        info->n_detections = int32_t(d.boxes.size());
        info->horizon_row = d.horizon_row;
        fill_stages(d.times, info->stages, info->n_stages);
        info->total_ms = d.total_ms;
        for (int32_t i = 0; i < std::min(cap, info->n_detections); ++i) out[i] = box_of(d.boxes[size_t(i)]);
        return HW_OK;
    });
}

int hw_pipeline_reset(hw_pipeline *p) {
    return guard([&] {
        require(p, "pipeline");
        std::lock_guard<std::mutex> lock(p->mu);
        require_stopped(p, "reset()");
        p->pipeline->reset();
        p->offline_frames = 0;
        return HW_OK;
    });
}

int hw_pipeline_set_ego_motion(hw_pipeline *p, double speed_mps, double yaw_rate_rps) {
    return guard([&] {
        require(p, "pipeline");
        p->pipeline->set_ego_motion(hw::EgoMotion{speed_mps, yaw_rate_rps});
        return HW_OK;
    });
}

int hw_pipeline_start(hw_pipeline *p, const char *source_json) {
    return guard([&] {
        require(p, "pipeline");
        require(source_json, "source description");
        std::lock_guard<std::mutex> lock(p->mu);
        require_stopped(p, "start()");
        auto source = hw::open_source(source_json, {p->config.camera.width, p->config.camera.height},
                                      p->config.pipeline.push_queue_capacity);
        p->loop.reset();
        p->loop = std::make_unique<hw::RealtimeLoop>(*p->pipeline, std::move(source), *p->results);
        p->loop->start();
        return HW_OK;
    });
}

int hw_pipeline_stop(hw_pipeline *p) {
    return guard([&] {
        require(p, "pipeline");
        std::lock_guard<std::mutex> lock(p->mu);
        if (p->loop) p->loop->stop();
        return HW_OK;
    });
}

int hw_pipeline_pop(hw_pipeline *p, int32_t timeout_ms, hw_frame_result *out) {
    return guard([&] {
        require(p, "pipeline");
        require(out, "out");
        if (!p->loop) throw hw::StateError("pop() before start(): nothing is running");
        hw::FrameOutput o;
        switch (p->results->pop(o, timeout_ms)) {
        case hw::ResultQueue<hw::FrameOutput>::Pop::Item: fill_result(o, out); return int(HW_OK);
        case hw::ResultQueue<hw::FrameOutput>::Pop::Timeout: return fail(HW_ERR_TIMEOUT, "no result within the timeout");
        case hw::ResultQueue<hw::FrameOutput>::Pop::Closed: {
            const std::string why = p->loop->failure();
            if (!why.empty()) return fail(HW_ERR_INTERNAL, "the real-time loop stopped: " + why);
            return fail(HW_ERR_END_OF_STREAM, "the source has ended and every result was popped");
        }
        }
        return int(HW_ERR_INTERNAL);
    });
}

int hw_pipeline_push(hw_pipeline *p, const uint8_t *data, int32_t width, int32_t height, int32_t channels,
                     int32_t stride, double t_s) {
    return guard([&] {
        require(p, "pipeline");
        require(data, "frame data");
        auto *push = p->loop ? dynamic_cast<hw::PushSource *>(&p->loop->source()) : nullptr;
        if (!push || !p->loop->running()) throw hw::StateError("push() needs a running pipeline started with a push source");
        if (channels != 1 && channels != 3 && channels != 4)
            throw std::invalid_argument("pushed frame must have 1, 3 or 4 channels, got " + std::to_string(channels));
        if (width <= 0 || height <= 0 || stride < width * channels)
            throw std::invalid_argument("pushed frame has a bad size or stride");
        cv::Mat img(height, width, CV_8UC(channels), const_cast<uint8_t *>(data), size_t(stride));
        push->push(img, t_s);
        return HW_OK;
    });
}

int hw_pipeline_push_end(hw_pipeline *p) {
    return guard([&] {
        require(p, "pipeline");
        auto *push = p->loop ? dynamic_cast<hw::PushSource *>(&p->loop->source()) : nullptr;
        if (!push) throw hw::StateError("push_end() needs a pipeline started with a push source");
        push->end();
        return HW_OK;
    });
}

int hw_pipeline_health(hw_pipeline *p, hw_health *out) {
    return guard([&] {
        require(p, "pipeline");
        require(out, "out");
        std::memset(out, 0, sizeof(*out));
        out->last_frame_t_s = NAN;
        out->last_progress_s = NAN;
        out->last_alive_s = NAN;
        out->last_total_ms = NAN;
        out->queue_capacity = p->results->capacity();
        if (p->loop) fill_health(p->loop->health(), *out);
        return HW_OK;
    });
}

} // extern "C"
