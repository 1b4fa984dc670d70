#include "core/config.hpp"

#include "core/parts.hpp"

#include <algorithm>

namespace hw {

using nlohmann::json;

namespace {

// The pipeline's own sections, in the order they are read.
template <class C, class Fn> void for_each_pipeline_section(C &c, Fn &&fn) {
    fn("camera", c.camera);
    fn("road", c.road);
    fn("vehicle_shape", c.vehicle_shape);
    fn("pipeline", c.pipeline);
    fn("lanes", c.lanes);
    fn("horizon", c.horizon);
    fn("self_calibration", c.self_calibration);
    fn("kinematics", c.kinematics);
    fn("lead", c.lead);
    fn("road_features", c.road_features);
    fn("homography", c.homography);
    fn("fuse", c.fuse);
}

// Applies `fn(name, params)` to every section, the pipeline's and the registered ones, so reading, writing and
// describing list them once.
template <class Fn> void for_each_section(Config &c, Fn &&fn) {
    for_each_pipeline_section(c, fn);
    c.parts.for_each(fn);
}

// Keys that moved to one shared definition: {old section, old key, new "section.key"}. A
// configuration that still uses one gets an error naming the new key, never a silent default.
struct MovedKey {
    const char *section, *key, *to;
};
constexpr MovedKey kMovedKeys[] = {
    {"lanes", "hood_frac", "camera.hood_frac"},
    {"parallax", "hood_frac", "camera.hood_frac"},
    {"shadow", "bottom_ignore_frac", "camera.hood_frac"},
    {"cascade", "bottom_ignore_frac", "camera.hood_frac"},
    {"lanes", "lane_width_m", "road.lane_width_m"},
    {"shadow", "lane_width_m", "road.lane_width_m"},
    {"cascade", "lane_width_m", "road.lane_width_m"},
    {"lead", "lane_width_m", "road.lane_width_m"},
    {"self_calibration", "lane_width_m", "road.lane_width_m"},
    {"lead", "min_lane_width_m", "road.min_lane_width_m"},
    {"lead", "max_lane_width_m", "road.max_lane_width_m"},
    {"shadow", "vehicle_width_m", "vehicle_shape.width_m"},
    {"cascade", "vehicle_width_m", "vehicle_shape.width_m"},
    {"parallax", "vehicle_width_m", "vehicle_shape.width_m"},
    {"road", "vehicle_width_m", "vehicle_shape.width_m"},
    {"cascade", "max_vehicle_height_m", "vehicle_shape.max_height_m"},
    {"parallax", "top_max_height_m", "vehicle_shape.max_height_m"},
    {"verify", "aspect_ratio", "vehicle_shape.aspect"},
    {"verify", "top_min_aspect", "vehicle_shape.top_min_aspect"},
    {"parallax", "top_min_aspect", "vehicle_shape.top_min_aspect"},
    {"verify", "top_max_aspect", "vehicle_shape.max_aspect"},
    {"parallax", "max_aspect", "vehicle_shape.max_aspect"},
    {"fuse", "thesis_weight", "fuse.cue_weight"},
    {"shadow", "grad_rel", "shadow_edge.grad_rel"},
    {"shadow", "min_step_gray", "shadow_edge.min_step_gray"},
    {"shadow", "dark_rel", "shadow_edge.dark_rel"},
};

void reject_moved_keys(const json &root) {
    for (const auto &m : kMovedKeys)
        if (root.contains(m.section) && root.at(m.section).is_object() && root.at(m.section).contains(m.key))
            throw ConfigError(std::string(m.section) + "." + m.key + ": moved to " + m.to +
                              " (one definition for every stage); set " + m.to + " instead");
}

// The preset's own keys (core/parts.cpp) fill in what the configuration leaves out: {"kinematics":
// {"box_margin_px": 1.5}} for default unless the configuration sets kinematics.box_margin_px. A
// section given as something other than a mapping is left for read_section to report.
void fill_preset_keys(json &root) {
    std::string preset = PipelineParams{}.preset;
    if (root.contains("pipeline") && root.at("pipeline").is_object() && root.at("pipeline").contains("preset") &&
        root.at("pipeline").at("preset").is_string())
        preset = root.at("pipeline").at("preset").get<std::string>();
    check_not_removed(preset);
    const json own = preset_keys(preset);  // kept alive: items() refers to it
    for (const auto &[section, keys] : own.items()) {
        if (!root.contains(section)) root[section] = json::object();
        json &given = root[section];
        if (!given.is_object()) continue;
        for (const auto &[key, value] : keys.items())
            if (!given.contains(key)) given[key] = value;
    }
}

// The road section is read once and handed to every pipeline unit that uses it (their `road` member); the
// registered sections take it themselves (their `share`).
void share_road(Config &c) {
    for (RoadParams *r : {&c.lanes.assembly.road, &c.lead.road, &c.self_calibration.road}) *r = c.road;
}

} // namespace

json Config::moved_keys() {
    json out = json::object();
    for (const auto &m : kMovedKeys) out[std::string(m.section) + "." + m.key] = m.to;
    return out;
}

Config Config::from_json(const std::string &text) {
    json root;
    try {
        root = text.empty() ? json::object() : json::parse(text);
    } catch (const json::parse_error &e) {
        throw ConfigError(std::string("configuration is not valid JSON: ") + e.what());
    }
    if (!root.is_object()) throw ConfigError("configuration: expected a mapping of sections");
    reject_moved_keys(root);
    fill_preset_keys(root);
    Config c;
    std::vector<std::string> known;
    for_each_section(c, [&](const char *name, auto &params) {
        known.emplace_back(name);
        read_section(root, name, params);
    });
    for (auto it = root.begin(); it != root.end(); ++it)
        if (std::find(known.begin(), known.end(), it.key()) == known.end())
            throw ConfigError(it.key() + ": unknown section of the core configuration");
    if (c.pipeline.reconnect_max_s < c.pipeline.reconnect_initial_s)
        throw ConfigError("pipeline.reconnect_max_s: must be >= pipeline.reconnect_initial_s");
    if (c.road.lane_width_m < c.road.min_lane_width_m || c.road.lane_width_m > c.road.max_lane_width_m)
        throw ConfigError("road.lane_width_m: must lie within [road.min_lane_width_m, road.max_lane_width_m], or "
                          "lead selection disbelieves every lane of the nominal width");
    if (c.self_calibration.pitch_min_deg >= c.self_calibration.pitch_max_deg)
        throw ConfigError("self_calibration.pitch_min_deg: must be below self_calibration.pitch_max_deg (the pitch "
                          "range searched, e.g. -5 to 20 deg)");
    share_road(c);
    c.parts.share(c);
    composition_of(c.pipeline);  // the parts exist and fit together
    return c;
}

const void *Config::find(const std::string &name, std::type_index type) const {
    const void *found = nullptr;
    for_each_pipeline_section(*this, [&](const char *n, const auto &params) {
        if (name == n && type == typeid(params)) found = &params;
    });
    return found ? found : parts.find(name, type);
}

void PipelineParams::bind(ParamMap &m) {
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

json Config::to_json() {
    json root = json::object();
    for_each_section(*this, [&](const char *name, auto &params) { write_section(root, name, params); });
    return root;
}

json Config::describe() {
    json root = json::object();
    for_each_section(*this, [&](const char *name, auto &params) { describe_section(root, name, params); });
    return root;
}

} // namespace hw
