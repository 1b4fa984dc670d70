// part_registry.hpp - the registries of parts (detectors, trackers): each part registers itself next to its
// factory, with its configuration section.
//
// One registration per part, in the part's own .cpp:
//
//     const bool registered = register_part<Detector, CascadeParams>(
//         "cascade", "cascade", [](const CascadeParams &p, const SectionLookup &c) { return std::make_unique<...>(p); });
//
// names the part, its section and struct (registered with it: register_section) and its factory, which may read
// the pipeline's sections (the camera, the road) and shared units' sections (verify, vehicle_shape) through `c`,
// never another part's: what two parts both need is a unit's section that both read
// (tests/cpp/core/test_part_sections.cpp). The core's parts registry (core/parts.cpp) builds a pipeline's parts
// from these, and the configuration's choices list them.
#pragma once

#include "base/sections.hpp"

#include <functional>
#include <map>
#include <memory>
#include <string>

namespace hw {

template <class Part> struct PartType {
    std::function<std::unique_ptr<Part>(const SectionLookup &)> make;
    bool needs_road_motion = false;  // a detector that compares two frames (the road-motion stage runs for it)
    std::string section;             // its configuration section (its subsections' owner)
};

// The registry of one role. A function-local static: registrars in other object files run in any order.
template <class Part> std::map<std::string, PartType<Part>> &part_registry() {
    static std::map<std::string, PartType<Part>> r;
    return r;
}

// Registers part `name` of role Part, built by `make(its section's struct, every section)`, and its section
// `section` holding struct P. Throws std::logic_error for a name taken.
template <class Part, class P, class Make>
bool register_part(const char *name, const char *section, Make make, bool needs_road_motion = false) {
    auto &r = part_registry<Part>();
    if (r.count(name)) throw std::logic_error(std::string("part '") + name + "' is registered twice");
    register_section<P>(section);
    const std::string s = section;
    r[name] = {[make, s](const SectionLookup &c) -> std::unique_ptr<Part> { return make(c.get<P>(s), c); },
               needs_road_motion, s};
    return true;
}

} // namespace hw
