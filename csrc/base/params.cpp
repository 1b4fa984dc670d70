#include "base/params.hpp"

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

// "a, b,c" -> {"a", "b", "c"}; empty names are dropped.
std::vector<std::string> split_names(const std::string &text) {
    std::vector<std::string> out;
    std::string cur;
    for (char ch : text + ",") {
        if (ch == ',') {
            if (!cur.empty()) out.push_back(cur);
            cur.clear();
        } else if (ch != ' ' && ch != '\t') {
            cur += ch;
        }
    }
    return out;
}

std::string join_names(const std::vector<std::string> &names) {
    std::string out;
    for (const auto &n : names) out += (out.empty() ? "" : ",") + n;
    return out;
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
                } else if constexpr (std::is_same_v<T, std::vector<std::string>>) {
                    // A list of names, or the same as one string separated by commas.
                    std::vector<std::string> names;
                    if (v.is_string()) {
                        names = split_names(v.get<std::string>());
                    } else if (v.is_array()) {
                        for (const auto &x : v) {
                            if (!x.is_string()) throw ConfigError(path + ": expected a list of names, got " + v.dump());
                            names.push_back(x.get<std::string>());
                        }
                    } else {
                        throw ConfigError(path + ": expected a list of names, got " + v.dump());
                    }
                    for (const auto &n : names)
                        if (e->choices && !in_choices(n, e->choices))
                            throw ConfigError(path + ": '" + n + "' is not one of " + e->choices);
                    *field = names;
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
        std::visit(
            [&](auto *field) {
                using T = std::remove_pointer_t<decltype(field)>;
                if constexpr (std::is_same_v<T, std::vector<std::string>>)
                    obj[e.key] = join_names(*field);
                else
                    obj[e.key] = *field;
            },
            e.field);
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
                } else if constexpr (std::is_same_v<T, std::vector<std::string>>) {
                    // Described as a string of names separated by commas (a YAML list is accepted too).
                    d["default"] = join_names(*field);
                    d["type"] = "str";
                    d["list"] = true;
                    if (e.choices) d["choices"] = e.choices;
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
