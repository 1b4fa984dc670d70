// config.hpp - the core's configuration: one parameter struct per unit, read from JSON.
#pragma once

#include "base/params.hpp"
#include "core/parts.hpp"
#include "detect/cascade_detector.hpp"
#include "detect/detector_proposals.hpp"
#include "detect/detector_parallax.hpp"
#include "detect/fuse_hypotheses.hpp"
#include "detect/lane_features.hpp"
#include "detect/verify.hpp"
#include "fcw/lead_selection.hpp"
#include "geometry/camera.hpp"
#include "geometry/horizon.hpp"
#include "geometry/road_params.hpp"
#include "geometry/self_calibration.hpp"
#include "geometry/track_kinematics.hpp"
#include "lanes/lane_tracker.hpp"
#include "road/road_motion_stage.hpp"
#include "track/particle_filter.hpp"
#include "track/tracker_kalman.hpp"
#include "track/tracker_phd.hpp"
#include "track/vehicle_height.hpp"

#include <string>

namespace hw {

// How the pipeline runs, independent of the method.
struct PipelineParams {
    std::string preset = "thesis";  // named composition of detector and tracker parts (core/parts.cpp); the core's own
                                    // default needs no model file; Headway's configuration defaults to "default"
                                    // (app/config.py, DEFAULT_PRESET), whose model paths Python fills in
    std::vector<std::string> detectors;  // detector parts replacing the preset's (empty: the preset's)
    std::string tracker;            // tracker part replacing the preset's (empty: the preset's)
    int queue_capacity = 8;         // results held for the caller before the oldest is dropped
    int push_queue_capacity = 4;    // pushed frames held before the oldest is dropped
    double reconnect_initial_s = 0.25;  // first back-off after a live source is lost
    double reconnect_max_s = 4.0;       // longest back-off between reconnect attempts
    int max_decode_errors = 50;     // consecutive undecodable frames before a recording is given up
    double debug_stall_after_s = 0.0;   // >0: the loop stops making progress after this many seconds (watchdog tests)

    void bind(ParamMap &m) {
        m.add("preset", preset, preset_choices(),
              "named composition of detector and tracker parts: default (learned detector with shadow cues, phd tracker), "
              "thesis, parallax, paper004 (the seed papers' methods), none (lanes only); docs/ARCHITECTURE.md, Presets");
        m.add("detectors", detectors, detector_choices(),
              "detector parts that replace the preset's, e.g. [shadow, parallax]; empty: the preset's; two or more "
              "are fused, learned detections first (docs/ARCHITECTURE.md)");
        m.add("tracker", tracker, tracker_choices(),
              "tracker part that replaces the preset's (kalman, particles, phd, none); empty: the preset's");
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
    CameraParams camera;              // also the hood line (camera.hood_frac) every stage stops at
    RoadParams road;                  // lane and vehicle widths; handed to every unit's `road` by from_json
    PipelineParams pipeline;
    LaneParams lanes;
    ShadowParams shadow;
    VerifyParams verify;
    KalmanBoxParams kalman;
    HorizonParams horizon;
    SelfCalibrationParams self_calibration;
    KinematicsParams kinematics;
    LeadParams lead;
    LaneFeatureParams road_features;  // road-motion stage: lane-marking features
    HomographyParams homography;      //   road homography (DLT + Kalman)
    ParallaxSection parallax;         //   aligned-difference detector and its road band
    ParticleParams particles;         //   joint particle filter
    CascadeParams cascade;            // cascade stage: the trained Haar cascade (docs/detection.md)
    ProposalsParams proposals;        // detector part proposals: the learned first stage (docs/detection.md)
    FuseParams fuse;                  // several detector parts: their hypotheses fused into one list
    PhdTrackerParams phd;             // tracker part phd (paper 004); its units in the next three sections
    VehicleHeightParams vehicle_height;  // a tracked vehicle's height (trucks); handed to kalman and phd by from_json

    // Parses the JSON text; throws ConfigError naming the key on any problem (a key that moved to
    // another section: naming the new one).
    static Config from_json(const std::string &text);
    // Keys that moved, "section.key" -> the key that replaced it, as from_json reports them.
    static nlohmann::json moved_keys();
    nlohmann::json to_json();        // effective values
    nlohmann::json describe();       // every key with type, range, default and doc
};

} // namespace hw
