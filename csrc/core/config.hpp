// config.hpp - the core's configuration: the pipeline's own sections and every registered part's, read from JSON.
#pragma once

#include "base/sections.hpp"
#include "detect/fuse_hypotheses.hpp"
#include "road/lane_features.hpp"
#include "fcw/lead_selection.hpp"
#include "geometry/camera.hpp"
#include "geometry/horizon.hpp"
#include "geometry/road_params.hpp"
#include "geometry/self_calibration.hpp"
#include "geometry/track_kinematics.hpp"
#include "geometry/vehicle_shape.hpp"
#include "lanes/lane_tracker.hpp"
#include "road/road_motion_stage.hpp"

#include <string>

namespace hw {

// How the pipeline runs, independent of the method.
struct PipelineParams {
    std::string preset = "thesis";  // named composition of detector and tracker parts (core/parts.cpp); a configuration
                                    // handed to the core without one runs this, which needs no model file; a
                                    // configuration file runs default_preset() (core/parts.cpp), whose model paths
                                    // Python fills in
    std::vector<std::string> detectors;  // detector parts replacing the preset's (empty: the preset's)
    std::string tracker;            // tracker part replacing the preset's (empty: the preset's)
    int queue_capacity = 8;         // results held for the caller before the oldest is dropped
    int push_queue_capacity = 4;    // pushed frames held before the oldest is dropped
    double reconnect_initial_s = 0.25;  // first back-off after a live source is lost
    double reconnect_max_s = 4.0;       // longest back-off between reconnect attempts
    int max_decode_errors = 50;     // consecutive undecodable frames before a recording is given up
    double debug_stall_after_s = 0.0;   // >0: the loop stops making progress after this many seconds (watchdog tests)

    void bind(ParamMap &m);  // its choices are the registered parts (core/parts.cpp)
};

// The pipeline's own sections by name; every part's section (detectors, trackers and what they are built from)
// is registered next to the part's factory (base/part_registry.hpp) and held in `parts`. A part reads any of them
// with get<Struct>("section").
struct Config final : SectionLookup {
    CameraParams camera;              // also the hood line (camera.hood_frac) every stage stops at
    RoadParams road;                  // lane widths; handed to every unit's `road` by from_json
    VehicleShapeParams vehicle_shape; // the vehicles' size and aspect; taken by every part's `share`
    PipelineParams pipeline;
    LaneParams lanes;
    HorizonParams horizon;
    SelfCalibrationParams self_calibration;
    KinematicsParams kinematics;
    LeadParams lead;
    LaneFeatureParams road_features;  // road-motion stage: lane-marking features
    HomographyParams homography;      //   road homography (DLT + Kalman)
    FuseParams fuse;                  // several detector parts: their hypotheses fused into one list
    Sections parts;                   // the registered sections of the parts

    // Parses the JSON text; throws ConfigError naming the key on any problem (a key that moved to
    // another section: naming the new one).
    static Config from_json(const std::string &text);
    // Keys that moved, "section.key" -> the key that replaced it, as from_json reports them.
    static nlohmann::json moved_keys();
    nlohmann::json to_json();        // effective values
    nlohmann::json describe();       // every key with type, range, default and doc

protected:
    const void *find(const std::string &name, std::type_index type) const override;
};

} // namespace hw
