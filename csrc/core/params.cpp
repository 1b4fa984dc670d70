#include "params.hpp"

#include <cmath>
#include <sstream>

namespace hw {

using nlohmann::json;

namespace {

std::string range_text(double min, double max) {
    std::ostringstream os;
    os << "[" << min << ", " << max << "]";
    return os.str();
}

bool in_choices(const std::string &v, const char *choices) {
    std::string all = std::string("|") + choices + "|";
    return all.find("|" + v + "|") != std::string::npos;
}

} // namespace

void ParamMap::read(const json &obj) const {
    if (!obj.is_object()) throw ConfigError(section_ + ": expected a mapping of keys to values");
    for (auto it = obj.begin(); it != obj.end(); ++it) {
        const Entry *e = nullptr;
        for (const auto &cand : entries_)
            if (it.key() == cand.key) e = &cand;
        const std::string path = section_ + "." + it.key();
        if (!e) throw ConfigError(path + ": unknown key");
        const json &v = it.value();
        std::visit(
            [&](auto *field) {
                using T = std::remove_pointer_t<decltype(field)>;
                if constexpr (std::is_same_v<T, double>) {
                    if (!v.is_number() || v.is_boolean())
                        throw ConfigError(path + ": expected a number, got " + v.dump());
                    const double d = v.get<double>();
                    if (!std::isfinite(d) || d < e->min || d > e->max)
                        throw ConfigError(path + ": " + v.dump() + " is outside " + range_text(e->min, e->max));
                    *field = d;
                } else if constexpr (std::is_same_v<T, int>) {
                    if (!v.is_number_integer())
                        throw ConfigError(path + ": expected an integer, got " + v.dump());
                    const auto i = v.get<long long>();
                    if (i < e->min || i > e->max)
                        throw ConfigError(path + ": " + v.dump() + " is outside " + range_text(e->min, e->max));
                    *field = int(i);
                } else if constexpr (std::is_same_v<T, bool>) {
                    if (!v.is_boolean()) throw ConfigError(path + ": expected true or false, got " + v.dump());
                    *field = v.get<bool>();
                } else {
                    if (!v.is_string()) throw ConfigError(path + ": expected a string, got " + v.dump());
                    const auto s = v.get<std::string>();
                    if (e->choices && !in_choices(s, e->choices))
                        throw ConfigError(path + ": '" + s + "' is not one of " + e->choices);
                    *field = s;
                }
            },
            e->field);
    }
}

void ParamMap::write(json &obj) const {
    if (!obj.is_object()) obj = json::object();
    for (const auto &e : entries_)
        std::visit([&](auto *field) { obj[e.key] = *field; }, e.field);
}

void ParamMap::describe(json &obj) const {
    if (!obj.is_object()) obj = json::object();
    for (const auto &e : entries_) {
        json d;
        std::visit(
            [&](auto *field) {
                using T = std::remove_pointer_t<decltype(field)>;
                d["default"] = *field;
                if constexpr (std::is_same_v<T, double>) {
                    d["type"] = "float"; d["min"] = e.min; d["max"] = e.max;
                } else if constexpr (std::is_same_v<T, int>) {
                    d["type"] = "int"; d["min"] = int(e.min); d["max"] = int(e.max);
                } else if constexpr (std::is_same_v<T, bool>) {
                    d["type"] = "bool";
                } else {
                    d["type"] = "str";
                    if (e.choices) d["choices"] = e.choices;
                }
            },
            e.field);
        d["doc"] = e.doc;
        obj[e.key] = d;
    }
}

} // namespace hw
