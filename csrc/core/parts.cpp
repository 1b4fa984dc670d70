#include "core/parts.hpp"

#include "core/config.hpp"
#include "detect/detector_cascade.hpp"
#include "detect/detector_parallax.hpp"
#include "detect/detector_proposals.hpp"
#include "detect/detector_shadow.hpp"
#include "track/tracker_kalman.hpp"
#include "track/tracker_particles.hpp"
#include "track/tracker_phd.hpp"

#include <functional>
#include <map>
#include <set>

namespace hw {

namespace {

template <class Part> using Factory = std::function<std::unique_ptr<Part>(const Config &)>;

// The detector registry: name -> how it is built from the configuration.
const std::map<std::string, Factory<Detector>> &detectors() {
    static const std::map<std::string, Factory<Detector>> r{
        {"shadow", [](const Config &c) { return std::make_unique<ShadowDetector>(c.shadow, c.verify); }},
        {"parallax", [](const Config &c) { return std::make_unique<ParallaxDifferenceDetector>(c.parallax, c.camera); }},
        {"cascade", [](const Config &c) { return std::make_unique<CascadeDetectorPart>(c.cascade); }},
        {"proposals", [](const Config &c) { return std::make_unique<ProposalsDetector>(c.proposals); }},
    };
    return r;
}

// The tracker registry.
const std::map<std::string, Factory<Tracker>> &trackers() {
    static const std::map<std::string, Factory<Tracker>> r{
        {"kalman", [](const Config &c) { return std::make_unique<KalmanTracker>(c.kalman, RoiSearch(c.shadow, c.verify)); }},
        {"particles", [](const Config &c) { return std::make_unique<ParticleTracker>(c.particles, c.camera); }},
        {"phd", [](const Config &c) { return std::make_unique<PhdTracker>(c.phd, c.camera, HorizonTracker(c.horizon, c.camera)); }},
    };
    return r;
}

// A named composition, and the keys it sets ({section: {key: value}}; a configuration's own value wins).
struct Preset {
    Composition parts;
    nlohmann::json keys = nlohmann::json::object();
};

// The named compositions: Headway's own (default) and the three seed papers' methods as they describe them.
// Other compositions are made with pipeline.detectors / pipeline.tracker.
const std::map<std::string, Preset> &presets() {
    static const std::map<std::string, Preset> r{
        // The learned detector (the cascade's proposals judged by the CNN verifier) as the primary source, the
        // shadow detector's verified bottom edges as a cue (detect/fuse_hypotheses.hpp); tracked by phd.
        {"default", {{{"cascade", "shadow"}, "phd"}}},
        {"thesis", {{{"shadow"}, "kalman"}}},      // shadows + vertical edges + Kalman
        {"parallax", {{{"parallax"}, "particles"}}},  // road homography + aligned difference + particle filter (paper 000)
        {"paper004", {{{"cascade"}, "phd"}}},      // Haar cascade + GM-PHD features + UKF (paper 004)
        {"none", {{{}, ""}}},                      // lanes only
    };
    return r;
}

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
        parts.detectors.parts.push_back(detectors().at(d)(cfg));
        road = road || parts.detectors.parts.back()->needs_road_motion();
    }
    parts.detectors.fuse = cfg.fuse;  // two or more detectors: fused (detect/fuse_hypotheses.hpp)
    if (!comp.tracker.empty()) parts.tracker = trackers().at(comp.tracker)(cfg);
    if (road) parts.road = std::make_unique<RoadMotionStage>(cfg.road_features, cfg.homography, cfg.parallax, cfg.camera);
    return parts;
}

} // namespace hw
