// Writer for `manikin-recording/1` (docs/formats.md section 1), and the instrument-spec helpers.
#include <charconv>
#include <cmath>
#include <cstdio>
#include <cstring>
#include <fstream>
#include <memory>

#include <fmt/core.h>
#include <nlohmann/json.hpp>

#include "analysis/input_error.hpp"
#include "analysis/recording.hpp"

namespace manikind::analysis {

double InstrumentSpec::limit(double reading) const {
    return accuracy + accuracy_of_reading * std::fabs(reading);
}

double InstrumentSpec::standard_uncertainty(double reading) const {
    const double a = limit(reading);
    switch (distribution) {
        case Distribution::rectangular: return a / std::sqrt(3.0);  // GUM 4.3.7
        case Distribution::normal_k2: return a / 2.0;                // stated as an expanded U at k = 2
        case Distribution::triangular: return a / std::sqrt(6.0);    // GUM 4.3.9
    }
    return a / std::sqrt(3.0);
}

const char* to_string(Distribution d) {
    switch (d) {
        case Distribution::rectangular: return "rectangular";
        case Distribution::normal_k2: return "normal";
        case Distribution::triangular: return "triangular";
    }
    return "rectangular";
}

std::optional<Distribution> distribution_from_string(const std::string& s) {
    if (s == "rectangular" || s == "uniform") return Distribution::rectangular;
    if (s == "normal" || s == "normal_k2" || s == "gaussian") return Distribution::normal_k2;
    if (s == "triangular") return Distribution::triangular;
    return std::nullopt;
}

std::map<std::string, InstrumentSpec> default_instrument_specs() {
    return {
        {"air_temp_c", {0.2, 0.0, Distribution::rectangular}},      // EE181, Tables S1-S2
        {"air_rh_pct", {1.4, 0.01, Distribution::rectangular}},     // EE181: ±(1.4 + 0.01 RH) %, Tables S1-S2
        {"air_speed_m_s", {0.02, 0.0, Distribution::rectangular}},  // SensoAnemo 5100 LSF, Table S1
        {"wall_temp_c", {0.5, 0.0, Distribution::rectangular}},     // Type-T thermocouple, Table S2
        {"skin_temp_c", {0.1, 0.0, Distribution::rectangular}},     // config/manikind.toml (not in the paper)
        {"heat_flux_w_m2", {1.0, 0.03, Distribution::rectangular}}, // config/manikind.toml (not in the paper)
    };
}

namespace {

struct FileCloser {
    void operator()(std::FILE* f) const { std::fclose(f); }
};

// Appends the shortest text that reads back to the same double (std::to_chars); NaN -> "".
void append_number(std::string& out, double v) {
    if (std::isnan(v)) return;
    char buf[32];
    const auto [ptr, ec] = std::to_chars(buf, buf + sizeof buf, v);
    (void)ec;  // 32 chars always suffice for a double
    out.append(buf, ptr);
}

void write_trial_csv(const std::filesystem::path& path, const ZoneMap& map, const TrialData& d) {
    const bool with_speed = !d.air_speed_m_s.empty();
    const bool with_wall = !d.wall_temp_c.empty();
    std::vector<const std::vector<double>*> cols{&d.t_s, &d.air_temp_c, &d.air_rh_pct};
    if (with_speed) cols.push_back(&d.air_speed_m_s);
    if (with_wall) cols.push_back(&d.wall_temp_c);
    if (d.skin_temp_c.size() != map.size() || d.heat_flux_w_m2.size() != map.size())
        throw std::invalid_argument(fmt::format("{}: trial data has {} zones, the map {}", path.string(),
                                                d.skin_temp_c.size(), map.size()));
    for (const auto& c : d.skin_temp_c) cols.push_back(&c);
    for (const auto& c : d.heat_flux_w_m2) cols.push_back(&c);
    for (const auto* c : cols)
        if (c->size() != d.t_s.size())
            throw std::invalid_argument(fmt::format("{}: a channel has {} samples, t_s has {}", path.string(), c->size(),
                                                    d.t_s.size()));

    std::unique_ptr<std::FILE, FileCloser> f(std::fopen(path.c_str(), "wb"));
    if (!f) throw InputError(path.string(), 0, 0, "", fmt::format("cannot write: {}", std::strerror(errno)));
    std::string out;
    const auto names = trial_csv_columns(map, with_speed, with_wall);
    for (std::size_t i = 0; i < names.size(); ++i) {
        if (i) out += ',';
        out += names[i];
    }
    out += '\n';
    // Written in blocks so memory stays flat however long the trial.
    constexpr std::size_t kFlushBytes = 1 << 18;
    for (std::size_t r = 0; r < d.t_s.size(); ++r) {
        for (std::size_t c = 0; c < cols.size(); ++c) {
            if (c) out += ',';
            append_number(out, (*cols[c])[r]);
        }
        out += '\n';
        if (out.size() >= kFlushBytes) {
            std::fwrite(out.data(), 1, out.size(), f.get());
            out.clear();
        }
    }
    std::fwrite(out.data(), 1, out.size(), f.get());
    if (std::fflush(f.get()) != 0 || std::ferror(f.get()))
        throw InputError(path.string(), 0, 0, "", fmt::format("write failed: {}", std::strerror(errno)));
}

}  // namespace

void write_campaign(const std::filesystem::path& folder, const Campaign& campaign) {
    using nlohmann::json;
    std::filesystem::create_directories(folder / "trials");
    json doc;
    doc["format"] = kRecordingFormat;
    doc["name"] = campaign.name;
    if (campaign.zone_map_inline || campaign.zone_map.name != "andi35") {
        json zones = json::array();
        for (const auto& z : campaign.zone_map.zones)
            zones.push_back({{"zone", z.zone}, {"name", z.name}, {"region", z.region}, {"segment", z.segment},
                             {"side", z.side}, {"area_m2", z.area_m2}, {"centroid_height_m", z.centroid_height_m}});
        doc["zone_map"] = zones;
    } else {
        doc["zone_map"] = "andi35";
    }
    json instruments = json::object();
    for (const auto& [channel, spec] : campaign.instruments) {
        json s{{"accuracy", spec.accuracy}, {"distribution", to_string(spec.distribution)}};
        if (spec.accuracy_of_reading != 0.0) s["accuracy_of_reading"] = spec.accuracy_of_reading;
        instruments[channel] = s;
    }
    doc["instruments"] = instruments;
    json trials = json::array();
    for (const auto& t : campaign.trials) {
        const auto& i = t.info;
        const std::string file = i.file.empty() ? "trials/" + i.id + ".csv" : i.file;
        json e{{"id", i.id}, {"case", i.case_id}, {"replicate", i.replicate}, {"file", file}};
        if (i.skin_setpoint_c) e["skin_setpoint_c"] = *i.skin_setpoint_c;
        if (i.wettedness) {
            if (*i.wettedness == 0.0 || *i.wettedness == 1.0) e["wet"] = *i.wettedness == 1.0;
            else e["wettedness"] = *i.wettedness;
        }
        if (i.chamber_setpoint_temp_c || i.chamber_setpoint_rh_pct) {
            json cs = json::object();
            if (i.chamber_setpoint_temp_c) cs["temp_c"] = *i.chamber_setpoint_temp_c;
            if (i.chamber_setpoint_rh_pct) cs["rh_pct"] = *i.chamber_setpoint_rh_pct;
            e["chamber_setpoint"] = cs;
        }
        if (!i.started_utc.empty()) e["started_utc"] = i.started_utc;
        trials.push_back(e);
        const std::filesystem::path csv = folder / file;
        std::filesystem::create_directories(csv.parent_path());
        write_trial_csv(csv, campaign.zone_map, t.data);
    }
    doc["trials"] = trials;
    std::ofstream out(folder / "campaign.json", std::ios::binary);
    if (!out) throw InputError((folder / "campaign.json").string(), 0, 0, "", "cannot write");
    out << doc.dump(2) << '\n';
}

}  // namespace manikind::analysis
