// A part reads its own section, the pipeline's sections and shared units' sections (verify, shadow_edge,
// vehicle_shape, ...), never another part's: a part's keys then configure that part alone, and a tracker composes
// with any detectors (base/part_registry.hpp). Checked for every registered part, through what its section's
// `share` and its factory look up.
#include "base/part_registry.hpp"
#include "core/config.hpp"
#include "cues/shadow.hpp"
#include "detect/detector.hpp"
#include "track/phd/part.hpp"
#include "track/tracker.hpp"

#include <doctest/doctest.h>

#include <set>
#include <string>
#include <typeindex>

namespace {

// The pipeline's own section of type P named `name`, if `type` is P (Config::get, which checks the name).
template <class... P>
const void *pipeline_section(const hw::Config &c, const std::string &name, std::type_index type) {
    const void *found = nullptr;
    ((found = found ? found : type == std::type_index(typeid(P)) ? &c.get<P>(name) : nullptr), ...);
    return found;
}

// The sections of a configuration, noting the name of each one looked up.
class RecordingLookup final : public hw::SectionLookup {
public:
    explicit RecordingLookup(const hw::Config &c) : c_(c) {}
    mutable std::set<std::string> asked;

protected:
    const void *find(const std::string &name, std::type_index type) const override {
        asked.insert(name);
        if (const void *p = c_.parts.find(name, type)) return p;
        // Config's own members (core/config.hpp); a part asking for one of another struct fails in Config::get.
        return pipeline_section<hw::CameraParams, hw::RoadParams, hw::VehicleShapeParams, hw::PipelineParams,
                                hw::LaneParams, hw::HorizonParams, hw::SelfCalibrationParams, hw::KinematicsParams,
                                hw::LeadParams, hw::LaneFeatureParams, hw::HomographyParams, hw::FuseParams>(
            c_, name, type);
    }

private:
    const hw::Config &c_;
};

// Every part's section, detectors' and trackers'.
std::set<std::string> part_sections() {
    std::set<std::string> out;
    for (const auto &[name, t] : hw::part_registry<hw::Detector>()) out.insert(t.section);
    for (const auto &[name, t] : hw::part_registry<hw::Tracker>()) out.insert(t.section);
    return out;
}

// The part section that `section` belongs to: itself, or the part section whose struct holds it (a subsection);
// empty for the pipeline's and shared units' sections.
std::string part_of(const std::string &section, const std::set<std::string> &parts) {
    std::string s = section;
    for (bool moved = true; moved && !parts.count(s);) {
        moved = false;
        for (const auto &t : hw::registered_sections())
            if (t.name == s && !t.owner.empty()) {
                s = t.owner;
                moved = true;
            }
    }
    return parts.count(s) ? s : std::string();
}

// The sections of other parts that the part with section `own` reads, separated by spaces: through the `share`
// of its section and of its subsections, and through its factory `make`.
template <class Make> std::string foreign_sections(const std::string &own, const Make &make, const hw::Config &c) {
    const std::set<std::string> parts = part_sections();
    RecordingLookup lookup(c);
    hw::Sections fresh;
    for (const auto &t : hw::registered_sections())
        if (t.share && part_of(t.name, parts) == own) t.share(fresh.find(t.name, t.type), lookup);
    try {
        make(lookup);
    } catch (const std::exception &) {
        // A model file it cannot open here: its sections were looked up before the part was built.
    }
    std::string out;
    for (const std::string &name : lookup.asked) {
        const std::string owner = part_of(name, parts);
        if (!owner.empty() && owner != own) out += (out.empty() ? "" : " ") + name;
    }
    return out;
}

template <class Part> void check_role(const std::string &role, const hw::Config &c) {
    for (const auto &[name, t] : hw::part_registry<Part>()) {
        const std::string what = role + " '" + name + "' reads another part's section";
        INFO(what);
        CHECK(foreign_sections(t.section, t.make, c) == "");
    }
}

} // namespace

TEST_CASE("no part reads another part's section") {
    const hw::Config c = hw::Config::from_json("{}");
    REQUIRE(hw::part_registry<hw::Tracker>().count("kalman"));
    check_role<hw::Detector>("detector", c);
    check_role<hw::Tracker>("tracker", c);
}

TEST_CASE("the check finds a look-up of another part's section, a subsection as its owner's") {
    const hw::Config c = hw::Config::from_json("{}");
    const auto reads_shadow = [](const hw::SectionLookup &l) { return l.get<hw::ShadowParams>("shadow").min_run_px; };
    CHECK(foreign_sections("kalman", reads_shadow, c) == "shadow");
    // A subsection is its owner's: phd's own, another part's to kalman.
    const auto reads_gmphd = [](const hw::SectionLookup &l) {
        return l.get<hw::GmPhdParams>("gmphd").survival_prob;
    };
    CHECK(foreign_sections("phd", reads_gmphd, c) == "");
    CHECK(foreign_sections("kalman", reads_gmphd, c) == "gmphd");
}
