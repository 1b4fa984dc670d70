// parts.hpp - the registries of detector and tracker parts, and the named compositions (presets).
//
// A pipeline is composed of detector parts (detect/detector.hpp) and one tracker part
// (track/tracker.hpp); the road-motion stage (road/road_motion_stage.hpp) runs when one of the parts
// needs it. The configuration names the parts: pipeline.preset picks a named composition,
// pipeline.detectors and pipeline.tracker, when set, replace the preset's detectors or tracker. A
// preset may also set keys of other sections (its defaults; the configuration's own value wins).
// One registry per role (base/part_registry.hpp): each part registers itself, with its configuration section,
// next to its factory in its own .cpp; adding a part is its two files and that one registration.
#pragma once

#include "detect/detector.hpp"
#include "detect/fuse_hypotheses.hpp"
#include "road/road_motion_stage.hpp"
#include "track/tracker.hpp"

#include <nlohmann/json.hpp>

#include <memory>
#include <string>
#include <vector>

namespace hw {

struct Config;
struct PipelineParams;

// The registered names, separated by '|' (for the configuration's choices).
const char *detector_choices();
const char *tracker_choices();
const char *preset_choices();

// Headway's default composition, the preset of a configuration file that names none.
const char *default_preset();

// Which parts run: the preset's, with pipeline.detectors / pipeline.tracker replacing its own when
// set. Throws ConfigError naming the key for a composition that cannot run.
struct Composition {
    std::vector<std::string> detectors;
    std::string tracker;  // empty: no tracker (lanes only)
};
Composition composition_of(const PipelineParams &p);

// A preset that was removed: throws ConfigError naming what replaces it (nothing for any other name).
void check_not_removed(const std::string &preset);
// {removed preset: what replaces it}, for the Python side's validation.
nlohmann::json describe_removed_presets();

// The keys a preset sets, {section: {key: value}}: defaults for that preset that a configuration still
// overrides key by key (Config::from_json fills them in where the configuration has none). Empty for a
// preset that sets none, or an unknown name (composition_of reports that).
nlohmann::json preset_keys(const std::string &preset);
// Every preset: {name: {"detectors": [...], "tracker": "...", "keys": {section: {key: value}}}}.
nlohmann::json describe_presets();

// {detector: {"single_image": whether it works on one image}}, for the Python side's choices.
nlohmann::json describe_detectors();

// One registered part built from the configuration; throws ConfigError naming the key for an unknown name.
std::unique_ptr<Detector> make_detector(const std::string &name, const Config &c);
std::unique_ptr<Tracker> make_tracker(const std::string &name, const Config &c);

// The parts of a configuration, built.
struct Parts {
    DetectorSet detectors;
    std::unique_ptr<Tracker> tracker;      // null: lanes only
    std::unique_ptr<RoadMotionStage> road; // null unless a part needs the road's motion
};
Parts make_parts(const Config &c);
} // namespace hw
