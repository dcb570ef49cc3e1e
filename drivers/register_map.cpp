#include "drivers/register_map.hpp"

#include <set>

#include <fmt/core.h>
#include <toml++/toml.h>

#include "base/toml_input.hpp"
#include "base/user_error.hpp"

namespace manikind {

namespace mr = protocol::modbus_registers;

const MappedRegister& RegisterMap::at(const std::string& name) const {
    for (const auto& r : registers)
        if (r.spec.name == name) return r;
    throw UserError(fmt::format("register map '{}' has no register '{}'", family, name));
}

RegisterMap parse_register_map(const std::string& text, const std::string& source) {
    const toml::table root = toml_input::parse(text, source);
    auto where = [&](const toml::node& n) { return toml_input::where(source, n); };
    RegisterMap map;
    map.family = root["family"].value_or(std::string("unnamed"));
    std::map<std::string, int> units;
    if (const auto* u = root["units"].as_table())
        for (const auto& [k, v] : *u) {
            if (!v.is_integer() || v.as_integer()->get() < 0 || v.as_integer()->get() > 247)
                throw UserError(fmt::format("{}: units.{}: expected a Modbus unit id 0..247", where(v), std::string(k.str())));
            units[std::string(k.str())] = static_cast<int>(v.as_integer()->get());
        }
    std::map<std::string, protocol::ProbeScaling> probes;
    if (const auto* pt = root["probes"].as_table())
        for (const auto& [k, v] : *pt) {
            const auto* t = v.as_table();
            if (!t) throw UserError(fmt::format("{}: probes.{}: expected a table", where(v), std::string(k.str())));
            protocol::ProbeScaling s;
            double* fields[] = {&s.raw_lo, &s.raw_hi, &s.lo, &s.hi};
            const char* keys[] = {"raw_lo", "raw_hi", "lo", "hi"};
            for (int i = 0; i < 4; ++i) {
                const auto* n = t->get(keys[i]);
                if (!n || !n->is_number())
                    throw UserError(fmt::format("{}: probes.{}.{}: expected a number", where(n ? *n : v), std::string(k.str()), keys[i]));
                *fields[i] = n->is_integer() ? static_cast<double>(n->as_integer()->get()) : n->as_floating_point()->get();
            }
            if (s.raw_hi == s.raw_lo) throw UserError(fmt::format("{}: probes.{}: raw_lo equals raw_hi", where(v), std::string(k.str())));
            probes[std::string(k.str())] = s;
        }
    const auto* regs = root["registers"].as_array();
    if (!regs) throw UserError(fmt::format("{}: no [[registers]] tables", source));
    std::set<std::string> names;
    for (const auto& node : *regs) {
        const auto* t = node.as_table();
        if (!t) throw UserError(fmt::format("{}: registers: expected [[registers]] tables", where(node)));
        MappedRegister r;
        auto text_of = [&](const char* key, bool required) -> std::string {
            const auto* n = t->get(key);
            if (!n) {
                if (required) throw UserError(fmt::format("{}: registers.{}: missing", where(node), key));
                return {};
            }
            if (!n->is_string()) throw UserError(fmt::format("{}: registers.{}: expected a string", where(*n), key));
            return n->as_string()->get();
        };
        auto number_of = [&](const char* key, double fallback) {
            const auto* n = t->get(key);
            if (!n) return fallback;
            if (!n->is_number()) throw UserError(fmt::format("{}: registers.{}: expected a number", where(*n), key));
            return n->is_integer() ? static_cast<double>(n->as_integer()->get()) : n->as_floating_point()->get();
        };
        r.spec.name = text_of("name", true);
        if (!names.insert(r.spec.name).second)
            throw UserError(fmt::format("{}: registers.name: '{}' appears twice", where(node), r.spec.name));
        const std::string unit = text_of("unit_id", true);
        if (!units.count(unit)) throw UserError(fmt::format("{}: registers.unit_id: '{}' is not in [units]", where(node), unit));
        r.unit_id = units[unit];
        const double address = number_of("address", -1);
        if (address < 0 || address > 65535 || address != static_cast<int>(address))
            throw UserError(fmt::format("{}: registers.address: expected 0..65535", where(node)));
        r.spec.address = static_cast<int>(address);
        const std::string type = text_of("type", true);
        static const std::map<std::string, mr::RegisterType> types = {
            {"int16", mr::RegisterType::int16}, {"uint16", mr::RegisterType::uint16}, {"int32", mr::RegisterType::int32},
            {"uint32", mr::RegisterType::uint32}, {"float32", mr::RegisterType::float32}};
        if (!types.count(type)) throw UserError(fmt::format("{}: registers.type: '{}' is not int16, uint16, int32, uint32 or float32", where(node), type));
        r.spec.type = types.at(type);
        r.spec.scale = number_of("scale", 1.0);
        if (r.spec.scale == 0.0) throw UserError(fmt::format("{}: registers.scale: must not be 0", where(node)));
        r.spec.offset = number_of("offset", 0.0);
        const std::string order = text_of("word_order", false);
        if (order == "low_word_first") r.spec.word_order = mr::WordOrder::low_word_first;
        else if (!order.empty() && order != "high_word_first")
            throw UserError(fmt::format("{}: registers.word_order: expected high_word_first or low_word_first", where(node)));
        const std::string access = text_of("access", true);
        if (access != "read" && access != "read_write")
            throw UserError(fmt::format("{}: registers.access: expected read or read_write", where(node)));
        r.spec.writable = access == "read_write";
        r.spec.min_value = number_of("min", -1e300);
        r.spec.max_value = number_of("max", 1e300);
        if (r.spec.writable && (r.spec.min_value <= -1e300 || r.spec.max_value >= 1e300))
            throw UserError(fmt::format("{}: registers: writable register '{}' needs min and max", where(node), r.spec.name));
        const std::string probe = text_of("probe", false);
        if (!probe.empty()) {
            if (!probes.count(probe)) throw UserError(fmt::format("{}: registers.probe: '{}' is not in [probes]", where(node), probe));
            r.probe = probes.at(probe);
        }
        r.valid_min = number_of("valid_min", -1e300);
        r.valid_max = number_of("valid_max", 1e300);
        map.registers.push_back(std::move(r));
    }
    return map;
}

RegisterMap load_register_map(const std::filesystem::path& path) {
    return parse_register_map(toml_input::read_text_file(path, "a TOML register map"), path.string());
}

namespace {
struct MapSource {
    std::string text;
    std::string name;  // for messages
};

MapSource register_map_source(const std::string& setting, const std::string& device,
                              const std::filesystem::path& base_dir) {
    if (setting == "builtin") {
        if (device == "chamber") return {builtin_chamber_registers_toml(), "config/chamber_registers.toml (built in)"};
        if (device == "datalogger") return {builtin_datalogger_registers_toml(), "config/datalogger_registers.toml (built in)"};
        throw UserError("no built-in register map for " + device);
    }
    std::filesystem::path p = setting;
    if (p.is_relative() && !base_dir.empty()) p = base_dir / p;
    return {toml_input::read_text_file(p, "a TOML register map"), p.string()};
}
}  // namespace

RegisterMap register_map_from_setting(const std::string& setting, const std::string& device,
                                      const std::filesystem::path& base_dir) {
    const MapSource source = register_map_source(setting, device, base_dir);
    return parse_register_map(source.text, source.name);
}

std::string register_map_text(const std::string& setting, const std::string& device,
                              const std::filesystem::path& base_dir) {
    return register_map_source(setting, device, base_dir).text;
}

std::vector<drivers::ModbusPoint> modbus_points(const RegisterMap& map) {
    std::vector<drivers::ModbusPoint> points;
    for (const auto& r : map.registers) {
        drivers::ModbusPoint p;
        p.channel = r.spec.name;
        p.spec = r.spec;
        p.unit_id = r.unit_id;
        p.scaling = r.probe;
        p.valid_min = r.valid_min;
        p.valid_max = r.valid_max;
        // Setpoints are written by the daemon; their read-back is the controller's working setpoint.
        p.poll = !r.spec.writable;
        points.push_back(std::move(p));
    }
    return points;
}

}  // namespace manikind
