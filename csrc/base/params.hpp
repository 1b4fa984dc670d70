// params.hpp - binds the fields of a parameter struct to configuration keys.
//
// Every algorithm keeps its tunables in a plain `Params` struct with defaults in the member
// initialisers. The struct's `bind(ParamMap&)` lists each field once, with its range, unit and the
// reason for its default; that one list reads the configuration JSON (rejecting unknown keys, wrong
// types and out-of-range values, naming the key), writes the effective configuration back out, and
// describes every key for `headway config doc`. The core is the single registry of its own keys.
#pragma once

#include <nlohmann/json.hpp>

#include <stdexcept>
#include <string>
#include <variant>
#include <vector>

namespace hw {

// Thrown for a configuration the core cannot use; the message names the key.
struct ConfigError : std::runtime_error {
    using std::runtime_error::runtime_error;
};

class ParamMap {
public:
    explicit ParamMap(std::string section) : section_(std::move(section)) {}

    // doc: "unit; what it is; why this default". min/max inclusive.
    void add(const char *key, double &v, double min, double max, const char *doc) {
        entries_.push_back({key, &v, min, max, doc});
    }
    void add(const char *key, int &v, int min, int max, const char *doc) {
        entries_.push_back({key, &v, double(min), double(max), doc});
    }
    void add(const char *key, bool &v, const char *doc) { entries_.push_back({key, &v, 0, 1, doc}); }
    // choices: the allowed values separated by '|'.
    void add(const char *key, std::string &v, const char *choices, const char *doc) {
        entries_.push_back({key, &v, 0, 0, doc, choices});
    }
    // A list of names, each one of `choices` (separated by '|').
    void add(const char *key, std::vector<std::string> &v, const char *choices, const char *doc) {
        entries_.push_back({key, &v, 0, 0, doc, choices});
    }

    // Reads the keys present in `obj` (a JSON object); keys not present keep their defaults.
    void read(const nlohmann::json &obj) const;
    // Writes every bound field into `obj`.
    void write(nlohmann::json &obj) const;
    // Writes {key: {"default"|"value", "type", "min", "max", "choices", "doc"}} into `obj`.
    void describe(nlohmann::json &obj) const;

private:
    struct Entry {
        const char *key;
        std::variant<double *, int *, bool *, std::string *, std::vector<std::string> *> field;
        double min = 0, max = 0;
        const char *doc = "";
        const char *choices = nullptr;
    };
    std::string section_;
    std::vector<Entry> entries_;
};

// Reads/writes one section of the configuration through a struct's bind().
template <class P> void read_section(const nlohmann::json &root, const char *name, P &params) {
    ParamMap m(name);
    params.bind(m);
    if (root.contains(name)) m.read(root.at(name));
}

template <class P> void write_section(nlohmann::json &root, const char *name, P &params) {
    ParamMap m(name);
    params.bind(m);
    m.write(root[name]);
}

template <class P> void describe_section(nlohmann::json &root, const char *name, P &params) {
    ParamMap m(name);
    params.bind(m);
    m.describe(root[name]);
}

} // namespace hw
