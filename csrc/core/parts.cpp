#include "core/parts.hpp"

#include "core/config.hpp"
#include "detect/detector_cascade.hpp"
#include "detect/detector_parallax.hpp"
#include "detect/detector_proposals.hpp"
#include "detect/merge_hypotheses.hpp"
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
        {"kalman", [](const Config &c) { return std::make_unique<KalmanTracker>(c.shadow, c.verify, c.kalman); }},
        {"particles", [](const Config &c) { return std::make_unique<ParticleTracker>(c.particles, c.parallax.max_dt_s, c.camera); }},
        {"phd", [](const Config &c) { return std::make_unique<PhdTracker>(c.horizon, c.phd, c.camera); }},
    };
    return r;
}

// A named composition, and the keys it sets ({section: {key: value}}; a configuration's own value wins).
struct Preset {
    Composition parts;
    nlohmann::json keys = nlohmann::json::object();
};

// The named compositions.
const std::map<std::string, Preset> &presets() {
    static const std::map<std::string, Preset> r{
        {"thesis", {{{"shadow"}, "kalman"}}},
        {"parallax", {{{"parallax"}, "particles"}}},
        {"parallax_kalman", {{{"parallax"}, "kalman"}}},
        {"shadow_particles", {{{"shadow"}, "particles"}}},
        {"phd", {{{"shadow"}, "phd"}}},
        {"cascade", {{{"cascade"}, "phd"}}},
        // Tracked, the cascade scans a car's sizes beyond 35 m on every full detection (the far vehicles only it
        // finds) and the nearer sizes in 4 turns (the shadows and parallax find those on every detection too): the
        // same tracks on the real clips, a p99 per frame ~28 % lower (docs/RESULTS.md, "Which is the default").
        {"fused", {{{"cascade", "shadow", "parallax"}, "kalman"}, {{"cascade", {{"tracked_slices", 4}, {"tracked_far_m", 35.0}}}}}},
        // The cascade's and the shadow detector's hypotheses merged, tracked by phd: a vehicle only the cascade
        // found is kept when its verifier probability is >= 0.9 and it stands within two lanes of the ego lane
        // (docs/RESULTS.md, "Preset `cascade_shadow_phd`").
        {"cascade_shadow_phd",
         {{{"cascade", "shadow"}, "phd"}, {{"merge", {{"min_appearance", 0.9}, {"appearance_lanes", 2}}}}}},
        {"none", {{{}, ""}}},
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
    // Several detectors: their hypotheses are merged and verified once (detect/merge_hypotheses.hpp).
    if (comp.detectors.size() > 1)
        parts.detectors.merge = std::make_shared<HypothesisMerge>(cfg.merge, cfg.verify, cfg.shadow.road);
    if (!comp.tracker.empty()) parts.tracker = trackers().at(comp.tracker)(cfg);
    if (road) parts.road = std::make_unique<RoadMotionStage>(cfg.road_features, cfg.homography, cfg.parallax, cfg.camera);
    return parts;
}

} // namespace hw
