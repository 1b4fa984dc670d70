// config.hpp - the core's configuration: one parameter struct per unit, read from JSON.
#pragma once

#include "core/params.hpp"
#include "detect/verify.hpp"
#include "fcw/lead_selection.hpp"
#include "geometry/horizon.hpp"
#include "geometry/track_kinematics.hpp"
#include "geometry/camera.hpp"
#include "lanes/lane_tracker.hpp"
#include "track/parallax_tracker.hpp"
#include "track/phd_tracker.hpp"
#include "track/thesis_tracker.hpp"

#include <string>

namespace hw {

// How the pipeline runs, independent of the method.
struct PipelineParams {
    std::string preset = "thesis";  // which detector + tracker
    int queue_capacity = 8;         // results held for the caller before the oldest is dropped
    int push_queue_capacity = 4;    // pushed frames held before the oldest is dropped
    double reconnect_initial_s = 0.25;  // first back-off after a live source is lost
    double reconnect_max_s = 4.0;       // longest back-off between reconnect attempts
    int max_decode_errors = 50;     // consecutive undecodable frames before a recording is given up
    double debug_stall_after_s = 0.0;   // >0: the loop stops making progress after this many seconds (watchdog tests)

    void bind(ParamMap &m) {
        m.add("preset", preset, "thesis|parallax|phd|none",
              "which detector + tracker runs: thesis (shadow + vertical edges + Kalman), parallax (road homography + "
              "aligned-difference detector + joint particle filter, paper 000), phd (shadow + vertical edges to find vehicles, "
              "their feature points by a GM-PHD filter and a UKF per vehicle, paper 004), none (lanes only)");
        m.add("queue_capacity", queue_capacity, 1, 1024,
              "results; queue to the supervisor; small so a slow consumer sees fresh results, the oldest is dropped and counted");
        m.add("push_queue_capacity", push_queue_capacity, 1, 1024,
              "frames; queue of frames pushed from Python; the oldest is dropped and counted");
        m.add("reconnect_initial_s", reconnect_initial_s, 0.01, 60.0,
              "s; first wait before reopening a lost live camera; doubles up to reconnect_max_s");
        m.add("reconnect_max_s", reconnect_max_s, 0.01, 600.0, "s; longest wait between reconnect attempts");
        m.add("max_decode_errors", max_decode_errors, 1, 100000,
              "frames; consecutive undecodable frames after which a recording is reported failed");
        m.add("debug_stall_after_s", debug_stall_after_s, 0.0, 1e6,
              "s; test hook: >0 makes the real-time loop hang after this long so the watchdog can be tested; keep 0");
    }
};

struct Config {
    CameraParams camera;
    PipelineParams pipeline;
    LaneParams lanes;
    ShadowParams shadow;
    VerifyParams verify;
    KalmanBoxParams kalman;
    HorizonParams horizon;
    KinematicsParams kinematics;
    LeadParams lead;
    LaneFeatureParams road_features;  // parallax preset: lane-marking features
    HomographyParams homography;      //   road homography (DLT + Kalman)
    ParallaxTrackerParams parallax;   //   aligned-difference detector
    ParticleParams particles;         //   joint particle filter
    PhdTrackerParams phd;             // phd preset (paper 004): the tracker; its parts in the next three sections

    // Parses the JSON text; throws ConfigError naming the key on any problem.
    static Config from_json(const std::string &text);
    nlohmann::json to_json();        // effective values
    nlohmann::json describe();       // every key with type, range, default and doc
};

} // namespace hw
