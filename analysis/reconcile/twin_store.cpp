#include "analysis/reconcile/twin_store.hpp"

#include <fstream>
#include <sstream>
#include <stdexcept>

#include <fmt/core.h>
#include <toml++/toml.h>

#include "base/toml_input.hpp"
#include "base/user_error.hpp"

namespace manikind::twin_store {
namespace tw = physics::twin;

tw::TwinVersion parse_twin_version(const std::string& text, const std::string& source) {
    const toml::table root = toml_input::parse(text, source);
    auto where = [&](const toml::node& n) { return toml_input::where(source, n); };
    tw::TwinVersion v;
    v.name = root["name"].value_or(std::string("unnamed"));
    if (const auto* terms = root.get("terms")) {
        if (!terms->is_array_of_tables()) throw UserError(fmt::format("{}: terms: expected [[terms]] tables", where(*terms)));
        for (const auto& node : *terms->as_array()) {
            const auto& t = *node.as_table();
            tw::Term term;
            const auto* name = t.get("name");
            if (!name || !name->is_string()) throw UserError(fmt::format("{}: terms.name: expected the term's name", where(node)));
            term.name = name->as_string()->get();
            for (const auto& [key, value] : t) {
                const std::string k(key.str());
                if (k == "name") continue;
                if (k == "region" || k == "input" || k == "pattern") {
                    if (!value.is_string()) throw UserError(fmt::format("{}: terms.{}: expected a string", where(value), k));
                    (k == "region" ? term.region : k == "input" ? term.input : term.pattern) = value.as_string()->get();
                } else if (k == "zones") {
                    if (!value.is_array()) throw UserError(fmt::format("{}: terms.zones: expected an array of zone numbers", where(value)));
                    for (const auto& z : *value.as_array()) {
                        if (!z.is_integer()) throw UserError(fmt::format("{}: terms.zones: expected integers", where(z)));
                        term.zones.push_back(static_cast<int>(z.as_integer()->get()));
                    }
                } else if (value.is_number()) {
                    term.parameters[k] = value.is_integer() ? static_cast<double>(value.as_integer()->get()) : value.as_floating_point()->get();
                } else {
                    throw UserError(fmt::format("{}: terms.{}: expected a number", where(value), k));
                }
            }
            try {
                tw::validate_term(term);
            } catch (const std::invalid_argument& e) {
                throw UserError(fmt::format("{}: {}", where(node), e.what()));
            }
            v.terms.push_back(std::move(term));
        }
    }
    return v;
}

tw::TwinVersion load_twin_version(const std::string& name_or_path) {
    if (name_or_path == "baseline") return tw::TwinVersion{};
    const auto text = toml_input::read_file(name_or_path);
    if (!text) throw UserError(fmt::format("--twin {}: not 'baseline' and not a readable twin-version TOML file", name_or_path));
    return parse_twin_version(*text, name_or_path);
}

std::string twin_version_to_toml(const tw::TwinVersion& v, const std::string& based_on, const std::string& note) {
    std::ostringstream o;
    o << "# manikind twin version: the baseline (docs/twin-baseline.md) plus these terms.\n";
    if (!note.empty()) o << "# " << note << "\n";
    o << fmt::format("name = \"{}\"\nbased_on = \"{}\"\n", v.name, based_on);
    for (const auto& t : v.terms) {
        o << fmt::format("\n[[terms]]\nname = \"{}\"\n", t.name);
        if (!t.region.empty()) o << fmt::format("region = \"{}\"\n", t.region);
        if (!t.input.empty()) o << fmt::format("input = \"{}\"\npattern = \"{}\"\n", t.input, t.pattern);
        if (!t.zones.empty()) {
            o << "zones = [";
            for (std::size_t i = 0; i < t.zones.size(); ++i) o << (i ? ", " : "") << t.zones[i];
            o << "]\n";
        }
        for (const auto& [k, val] : t.parameters) o << fmt::format("{} = {:.17g}\n", k, val);
    }
    return o.str();
}

void save_twin_version(const tw::TwinVersion& v, const std::filesystem::path& path, const std::string& based_on,
                       const std::string& note) {
    std::ofstream out(path, std::ios::binary);
    out << twin_version_to_toml(v, based_on, note);
    if (!out) throw UserError(fmt::format("{}: cannot write the twin version", path.string()));
}

}  // namespace manikind::twin_store
