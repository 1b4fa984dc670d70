// The shadow edge (section shadow_edge): on a road of gray level g a shadow-edge pixel has a Sobel step of at least
// 4 max(min_step_gray, grad_rel g) and a pixel above it no brighter than dark_rel g; the shadow detector's section
// takes these from shadow_edge (its share), the section the Kalman tracker's ROI search reads as well.
#include "cues/shadow.hpp"

#include <doctest/doctest.h>

#include <string>
#include <typeindex>

TEST_CASE("shadow thresholds follow the road's gray level, the step floored on dark roads") {
    const hw::ShadowEdgeParams p;  // grad_rel 0.12, min_step_gray 6, dark_rel 0.5
    const hw::ShadowThresholds bright = hw::shadow_thresholds(100.f, p);
    CHECK(bright.grad == 48);  // 4 x 12 gray levels
    CHECK(bright.dark == 50);
    const hw::ShadowThresholds dark = hw::shadow_thresholds(20.f, p);
    CHECK(dark.grad == 24);  // 0.12 x 20 = 2.4 is below the floor of 6
    CHECK(dark.dark == 10);
}

namespace {

// The three sections the shadow detector's struct takes.
class Shared final : public hw::SectionLookup {
public:
    hw::ShadowEdgeParams edge;
    hw::RoadParams road;
    hw::VehicleShapeParams shape;

protected:
    const void *find(const std::string &name, std::type_index type) const override {
        if (name == "shadow_edge" && type == typeid(hw::ShadowEdgeParams)) return &edge;
        if (name == "road" && type == typeid(hw::RoadParams)) return &road;
        if (name == "vehicle_shape" && type == typeid(hw::VehicleShapeParams)) return &shape;
        return nullptr;
    }
};

} // namespace

TEST_CASE("the shadow detector's section takes the shadow edge from section shadow_edge") {
    Shared shared;
    shared.edge.grad_rel = 0.2;
    shared.edge.min_step_gray = 3.0;
    shared.edge.dark_rel = 0.4;
    hw::ShadowParams p;
    p.share(shared);
    CHECK(p.edge.grad_rel == 0.2);
    CHECK(p.edge.min_step_gray == 3.0);
    CHECK(p.edge.dark_rel == 0.4);
    hw::ParamMap keys("shadow");
    p.bind(keys);
    nlohmann::json described;
    keys.describe(described);
    for (const char *key : {"grad_rel", "min_step_gray", "dark_rel"}) {
        INFO(key, " is a key of shadow_edge only");
        CHECK_FALSE(described.contains(key));
    }
}
