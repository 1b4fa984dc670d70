// sections.hpp - the configuration's sections, each registered by the unit that owns its parameter struct.
//
// A unit registers its struct under a section name once (register_section, or register_part in
// base/part_registry.hpp next to a part's factory); the core's Config then reads, writes and describes every
// registered section without listing them. A section may also live inside another's struct (the phd tracker
// holds gmphd, phd_features, ...: register_subsection). Parts look sections up by name and struct
// (SectionLookup::get), the pipeline's own sections (camera, road, horizon) included.
#pragma once

#include "base/params.hpp"

#include <functional>
#include <memory>
#include <stdexcept>
#include <string>
#include <type_traits>
#include <typeindex>
#include <vector>

namespace hw {

// Looks a section up by name and struct.
class SectionLookup {
public:
    // Throws std::logic_error when no section of that name holds a P (a part asking for what is not registered).
    template <class P> const P &get(const std::string &name) const {
        const void *p = find(name, typeid(P));
        if (!p) throw std::logic_error("configuration section '" + name + "' is not registered with this struct");
        return *static_cast<const P *>(p);
    }

protected:
    ~SectionLookup() = default;
    virtual const void *find(const std::string &name, std::type_index type) const = 0;
};

// A section's struct that takes shared constants from other sections (the road's widths, the vehicle's
// height) has `void share(const SectionLookup &)`; Config::from_json calls it once every section is read.
template <class P, class = void> struct HasShare : std::false_type {};
template <class P>
struct HasShare<P, std::void_t<decltype(std::declval<P &>().share(std::declval<const SectionLookup &>()))>>
    : std::true_type {};

// How one registered section's struct is made, copied, bound to its keys and handed the shared constants.
struct SectionType {
    std::string name;
    std::string owner;  // empty: a struct of its own; else the section whose struct holds it
    std::type_index type;
    std::function<std::shared_ptr<void>()> make;             // a struct with its defaults (own sections)
    std::function<std::shared_ptr<void>(const void *)> copy; // (own sections)
    std::function<void *(void *owner)> member;               // where it lives in the owner's struct (subsections)
    std::function<void(void *, ParamMap &)> bind;
    std::function<void(void *, const SectionLookup &)> share;  // null: takes nothing from other sections
};

// Every registered section, in registration order. A function-local static: registrars in other object files
// run in any order before main.
std::vector<SectionType> &registered_sections();
// Adds one; throws std::logic_error for a name already registered (two units cannot own one section).
void add_section_type(SectionType t);

template <class P> SectionType section_type(const char *name, const char *owner) {
    SectionType t{name, owner, typeid(P), nullptr, nullptr, nullptr,
                  [](void *p, ParamMap &m) { static_cast<P *>(p)->bind(m); }, nullptr};
    if constexpr (HasShare<P>::value) t.share = [](void *p, const SectionLookup &c) { static_cast<P *>(p)->share(c); };
    return t;
}

template <class P> bool register_section(const char *name) {
    SectionType t = section_type<P>(name, "");
    t.make = [] { return std::make_shared<P>(); };
    t.copy = [](const void *p) { return std::make_shared<P>(*static_cast<const P *>(p)); };
    add_section_type(std::move(t));
    return true;
}

// A section whose struct is the member `member` of section `owner`'s struct `Owner`.
template <class Owner, class P> bool register_subsection(const char *name, const char *owner, P Owner::*member) {
    SectionType t = section_type<P>(name, owner);
    t.member = [member](void *o) -> void * { return &(static_cast<Owner *>(o)->*member); };
    add_section_type(std::move(t));
    return true;
}

// The registered sections' structs, one each with its defaults; copies are deep.
class Sections {
public:
    Sections();
    Sections(const Sections &other);
    Sections &operator=(const Sections &other);

    // null when `name` is not registered or holds another struct.
    void *find(const std::string &name, std::type_index type);
    const void *find(const std::string &name, std::type_index type) const;
    // Hands every section that has `share` what it takes from the others.
    void share(const SectionLookup &all);

    // fn(name, params), params binding the section's keys (`params.bind(ParamMap &)`, as read_section takes).
    struct Bound {
        void *obj;
        const SectionType *type;
        void bind(ParamMap &m) { type->bind(obj, m); }
    };
    template <class Fn> void for_each(Fn &&fn) {
        for (const auto &t : registered_sections()) {
            Bound b{object_of(t), &t};
            fn(t.name.c_str(), b);
        }
    }

private:
    void *object_of(const SectionType &t) const;
    std::vector<std::shared_ptr<void>> own_;  // parallel to registered_sections(); null for subsections
};

} // namespace hw
