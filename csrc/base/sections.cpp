#include "base/sections.hpp"

namespace hw {

std::vector<SectionType> &registered_sections() {
    static std::vector<SectionType> r;
    return r;
}

void add_section_type(SectionType t) {
    for (const auto &s : registered_sections())
        if (s.name == t.name) throw std::logic_error("configuration section '" + t.name + "' is registered twice");
    registered_sections().push_back(std::move(t));
}

Sections::Sections() {
    for (const auto &t : registered_sections()) own_.push_back(t.make ? t.make() : nullptr);
}

Sections::Sections(const Sections &other) { *this = other; }

Sections &Sections::operator=(const Sections &other) {
    if (this == &other) return *this;
    own_.clear();
    const auto &types = registered_sections();
    for (size_t i = 0; i < types.size(); ++i) {
        const bool has = i < other.own_.size() && other.own_[i];
        own_.push_back(!types[i].make ? nullptr : has ? types[i].copy(other.own_[i].get()) : types[i].make());
    }
    return *this;
}

void *Sections::object_of(const SectionType &t) const {
    const auto &types = registered_sections();
    for (size_t i = 0; i < types.size() && i < own_.size(); ++i) {
        if (t.owner.empty() ? &types[i] == &t : types[i].name == t.owner)
            return t.owner.empty() ? own_[i].get() : t.member(own_[i].get());
    }
    return nullptr;
}

void Sections::share(const SectionLookup &all) {
    for (const auto &t : registered_sections())
        if (t.share) t.share(object_of(t), all);
}

void *Sections::find(const std::string &name, std::type_index type) {
    for (const auto &t : registered_sections())
        if (t.name == name) return t.type == type ? object_of(t) : nullptr;
    return nullptr;
}

const void *Sections::find(const std::string &name, std::type_index type) const {
    return const_cast<Sections *>(this)->find(name, type);
}

} // namespace hw
