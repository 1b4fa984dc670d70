#include "core/parts.hpp"

#include "base/part_registry.hpp"
#include "core/config.hpp"

#include <functional>
#include <map>
#include <set>

namespace hw {

namespace {

// The registries: each part registers itself next to its factory (base/part_registry.hpp).
const std::map<std::string, PartType<Detector>> &detectors() { return part_registry<Detector>(); }
const std::map<std::string, PartType<Tracker>> &trackers() { return part_registry<Tracker>(); }

// A named composition, and the keys it sets ({section: {key: value}}; a configuration's own value wins).
struct Preset {
    Composition parts;
    nlohmann::json keys = nlohmann::json::object();
};

// TuSimple's annotation margin, 2-3 px for boxes 10-30 px high and 3-5 px at 30-60 px: 1.5 px + 0.06 x height.
nlohmann::json learned_box_margin() {
    return {{"kinematics", {{"box_margin_px", 1.5}, {"box_margin_frac", 0.06}}}};
}

// The named compositions: Headway's own (default) and the three seed papers' methods as they describe them.
// Other compositions are made with pipeline.detectors / pipeline.tracker.
const std::map<std::string, Preset> &presets() {
    static const std::map<std::string, Preset> r{
        // The learned detector (the cascade's proposals judged by the CNN verifier) as the primary source, the
        // shadow detector's verified bottom edges as a cue (detect/fuse_hypotheses.hpp); tracked by phd.
        // The learned detector's boxes carry its training boxes' margin beyond the vehicle's sides; the tracked
        // vehicles are reported without it (geometry/track_kinematics.hpp, docs/tracking.md).
        {"default", {{{"cascade", "shadow"}, "phd"}, learned_box_margin()}},
        {"thesis", {{{"shadow"}, "kalman"}}},      // shadows + vertical edges + Kalman
        {"parallax", {{{"parallax"}, "particles"}}},  // road homography + aligned difference + particle filter (paper 000)
        {"paper004", {{{"cascade"}, "phd"}, learned_box_margin()}},  // Haar cascade + GM-PHD features + UKF (paper 004)
        {"none", {{{}, ""}}},                      // lanes only
    };
    return r;
}

} // namespace

// Named here once: a configuration file that names no preset runs it (app/config.py reads it through
// hw_pipeline_config(NULL, ...), "default_preset"). A configuration handed to the core alone without a preset
// runs PipelineParams' own (core/config.hpp), which needs no model file.
const char *default_preset() { return "default"; }

namespace {

// Presets that no longer exist, and what replaces each: a configuration naming one gets an error saying so.
const std::map<std::string, std::string> &removed_presets() {
    static const std::map<std::string, std::string> r{
        {"fused", "preset default"},
        {"cascade_shadow_phd", "preset default"},
        {"cascade", "preset paper004"},
        {"phd", "pipeline: {detectors: [shadow], tracker: phd}"},
        {"parallax_kalman", "pipeline: {detectors: [parallax], tracker: kalman}"},
        {"shadow_particles", "pipeline: {detectors: [shadow], tracker: particles}"},
    };
    return r;
}

template <class Map> std::string joined(const Map &m, const std::string &first = "") {
    std::string s = first;
    for (const auto &kv : m) s += (s.empty() ? "" : "|") + kv.first;
    return s;
}

} // namespace

const char *detector_choices() {
    static const std::string s = joined(detectors());
    return s.c_str();
}

const char *tracker_choices() {
    // The empty name keeps the preset's tracker; "none" runs no tracker.
    static const std::string s = "|" + joined(trackers()) + "|none";
    return s.c_str();
}

const char *preset_choices() {
    static const std::string s = joined(presets());
    return s.c_str();
}

Composition composition_of(const PipelineParams &p) {
    const auto preset = presets().find(p.preset);
    check_not_removed(p.preset);
    if (preset == presets().end())
        throw ConfigError("pipeline.preset: unknown preset '" + p.preset + "' (one of " + preset_choices() + ")");
    Composition c = preset->second.parts;
    if (!p.detectors.empty()) c.detectors = p.detectors;
    if (!p.tracker.empty()) c.tracker = p.tracker == "none" ? "" : p.tracker;
    std::set<std::string> seen;
    for (const auto &d : c.detectors) {
        if (!detectors().count(d))
            throw ConfigError("pipeline.detectors: unknown detector '" + d + "' (one of " + detector_choices() + ")");
        if (!seen.insert(d).second) throw ConfigError("pipeline.detectors: '" + d + "' is listed twice");
    }
    if (!c.tracker.empty() && !trackers().count(c.tracker))
        throw ConfigError("pipeline.tracker: unknown tracker '" + c.tracker + "' (one of " + tracker_choices() + ")");
    if (!c.tracker.empty() && c.detectors.empty())
        throw ConfigError("pipeline.tracker: tracker '" + c.tracker + "' has no detector to ask: set pipeline.detectors "
                          "(one or more of " + std::string(detector_choices()) + ") or a preset that has one");
    if (c.tracker.empty() && !c.detectors.empty())
        throw ConfigError("pipeline.detectors: detectors need a tracker: set pipeline.tracker (one of " +
                          joined(trackers()) + ") or a preset that has one");
    return c;
}

void check_not_removed(const std::string &preset) {
    const auto removed = removed_presets().find(preset);
    if (removed != removed_presets().end())
        throw ConfigError("pipeline.preset: preset '" + preset + "' was removed; use " + removed->second);
}

nlohmann::json describe_removed_presets() {
    nlohmann::json out = nlohmann::json::object();
    for (const auto &[name, use] : removed_presets()) out[name] = use;
    return out;
}

nlohmann::json describe_detectors() {
    nlohmann::json out = nlohmann::json::object();
    for (const auto &[name, d] : detectors()) out[name] = {{"single_image", !d.needs_road_motion}};
    return out;
}

std::unique_ptr<Detector> make_detector(const std::string &name, const Config &c) {
    const auto it = detectors().find(name);
    if (it == detectors().end())
        throw ConfigError("pipeline.detectors: unknown detector '" + name + "' (one of " + detector_choices() + ")");
    auto d = it->second.make(c);
    if (d->needs_road_motion() != it->second.needs_road_motion)  // the registration says what the part does
        throw std::logic_error("detector '" + name + "': its registration and needs_road_motion() disagree");
    return d;
}

std::unique_ptr<Tracker> make_tracker(const std::string &name, const Config &c) {
    const auto it = trackers().find(name);
    if (it == trackers().end())
        throw ConfigError("pipeline.tracker: unknown tracker '" + name + "' (one of " + tracker_choices() + ")");
    return it->second.make(c);
}

nlohmann::json preset_keys(const std::string &preset) {
    const auto it = presets().find(preset);
    return it == presets().end() ? nlohmann::json::object() : it->second.keys;
}

nlohmann::json describe_presets() {
    nlohmann::json out = nlohmann::json::object();
    for (const auto &[name, p] : presets())
        out[name] = {{"detectors", p.parts.detectors}, {"tracker", p.parts.tracker}, {"keys", p.keys}};
    return out;
}

Parts make_parts(const Config &cfg) {
    const Composition comp = composition_of(cfg.pipeline);
    Parts parts;
    bool road = false;
    for (const auto &d : comp.detectors) {
        parts.detectors.parts.push_back(make_detector(d, cfg));
        road = road || parts.detectors.parts.back()->needs_road_motion();
    }
    parts.detectors.fuse = cfg.fuse;  // two or more detectors: fused (detect/fuse_hypotheses.hpp)
    if (!comp.tracker.empty()) parts.tracker = make_tracker(comp.tracker, cfg);
    if (road)
        parts.road = std::make_unique<RoadMotionStage>(cfg.road_features, cfg.homography,
                                                       cfg.get<ParallaxSection>("parallax"), cfg.camera);
    return parts;
}

} // namespace hw
