// ParamMap: a configuration section is read key by key into its struct; an unknown key, a wrong type or a value
// out of range is refused with a message naming section.key, and what is written back is what was read.
#include "base/params.hpp"

#include <doctest/doctest.h>

namespace {

struct Example {
    double gain = 0.5;
    int frames = 3;
    bool on = false;
    std::string mode = "fast";
    void bind(hw::ParamMap &m) {
        m.add("gain", gain, 0.0, 1.0, "1; a gain");
        m.add("frames", frames, 1, 10, "frames; a count");
        m.add("on", on, "a switch");
        m.add("mode", mode, "fast|slow", "a choice");
    }
};

} // namespace

TEST_CASE("a section is read into its struct, keys absent keep their defaults, and written back") {
    Example e;
    hw::read_section({{"example", {{"gain", 0.25}, {"mode", "slow"}}}}, "example", e);
    CHECK(e.gain == 0.25);
    CHECK(e.mode == "slow");
    CHECK(e.frames == 3);
    CHECK_FALSE(e.on);
    nlohmann::json out;
    hw::write_section(out, "example", e);
    CHECK(out["example"]["gain"] == 0.25);
    CHECK(out["example"]["frames"] == 3);
    CHECK(out["example"]["mode"] == "slow");
}

TEST_CASE("bad values are refused naming section.key and what is allowed") {
    Example e;
    hw::ParamMap m("example");
    e.bind(m);
    CHECK_THROWS_WITH_AS(m.read({{"gain", 1.5}}), doctest::Contains("example.gain"), hw::ConfigError);
    CHECK_THROWS_WITH_AS(m.read({{"frames", 11}}), doctest::Contains("example.frames"), hw::ConfigError);
    CHECK_THROWS_WITH_AS(m.read({{"frames", 2.5}}), doctest::Contains("example.frames"), hw::ConfigError);
    CHECK_THROWS_WITH_AS(m.read({{"mode", "medium"}}), doctest::Contains("fast|slow"), hw::ConfigError);
    CHECK_THROWS_WITH_AS(m.read({{"gian", 0.1}}), doctest::Contains("example.gian: unknown key"), hw::ConfigError);
    CHECK_THROWS_WITH_AS(m.read({{"on", "yes"}}), doctest::Contains("example.on"), hw::ConfigError);
    // a refused read leaves the defaults (the struct is not half-written by an earlier valid key)
    CHECK(e.frames == 3);
}

TEST_CASE("describe lists every key with its range and doc") {
    Example e;
    hw::ParamMap m("example");
    e.bind(m);
    nlohmann::json d;
    m.describe(d);
    CHECK(d.size() == 4);
    CHECK(d["gain"]["min"] == 0.0);
    CHECK(d["gain"]["max"] == 1.0);
    CHECK(d["frames"]["max"] == 10);
    CHECK(d["gain"]["doc"] == "1; a gain");
}
