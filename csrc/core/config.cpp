#include "core/config.hpp"

#include <algorithm>

namespace hw {

using nlohmann::json;

namespace {

// Applies `fn(name, params)` to every section, so reading, writing and describing list them once.
template <class Fn> void for_each_section(Config &c, Fn &&fn) {
    fn("camera", c.camera);
    fn("pipeline", c.pipeline);
    fn("lanes", c.lanes);
    fn("shadow", c.shadow);
    fn("verify", c.verify);
    fn("kalman", c.kalman);
    fn("horizon", c.horizon);
    fn("self_calibration", c.self_calibration);
    fn("kinematics", c.kinematics);
    fn("lead", c.lead);
    fn("road_features", c.road_features);
    fn("homography", c.homography);
    fn("parallax", c.parallax);
    fn("particles", c.particles);
    fn("cascade", c.cascade);
    fn("fuse", c.fuse);
    fn("merge", c.merge);
    fn("phd", c.phd);
    fn("gmphd", c.phd.phd);
    fn("phd_features", c.phd.features);
    fn("phd_ukf", c.phd.ukf);
}

} // namespace

Config Config::from_json(const std::string &text) {
    json root;
    try {
        root = text.empty() ? json::object() : json::parse(text);
    } catch (const json::parse_error &e) {
        throw ConfigError(std::string("configuration is not valid JSON: ") + e.what());
    }
    if (!root.is_object()) throw ConfigError("configuration: expected a mapping of sections");
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
    composition_of(c.pipeline);  // the parts exist and fit together
    return c;
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
