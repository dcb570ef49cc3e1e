// Writer for `manikin-recording/2` (docs/formats.md section 1), and the instrument-spec helpers.
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

double standardised_error_draw(Distribution d, std::mt19937_64& rng) {
    std::uniform_real_distribution<double> u(-1.0, 1.0);
    std::normal_distribution<double> n(0.0, 0.5);  // a k = 2 limit: u = a/2
    switch (d) {
        case Distribution::rectangular: return u(rng);
        case Distribution::normal_k2: return n(rng);
        case Distribution::triangular: return 0.5 * (u(rng) + u(rng));
    }
    return u(rng);
}

InstrumentSpec Campaign::instrument(const std::string& channel) const {
    const auto it = instruments.find(channel);
    return it == instruments.end() ? InstrumentSpec{} : it->second;
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

struct WrittenFileCloser {
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

void write_trial_csv(const std::filesystem::path& path, const ZoneMap& map, const std::vector<RecordedChannel>& channels,
                     const TrialData& d) {
    const bool with_speed = !d.air_speed_m_s.empty();
    const bool with_wall = !d.wall_temp_c.empty();
    const bool with_utc = !d.utc_ns.empty();
    std::vector<const std::vector<double>*> cols{&d.air_temp_c, &d.air_rh_pct};
    if (with_speed) cols.push_back(&d.air_speed_m_s);
    if (with_wall) cols.push_back(&d.wall_temp_c);
    if (d.skin_temp_c.size() != map.size() || d.heat_flux_w_m2.size() != map.size())
        throw std::invalid_argument(fmt::format("{}: trial data has {} zones, the map {}", path.string(),
                                                d.skin_temp_c.size(), map.size()));
    for (const auto& c : d.skin_temp_c) cols.push_back(&c);
    for (const auto& c : d.heat_flux_w_m2) cols.push_back(&c);
    const std::size_t n = d.t_s.size();
    for (const auto* c : cols)
        if (c->size() != n)
            throw std::invalid_argument(fmt::format("{}: a channel has {} samples, t_s has {}", path.string(), c->size(), n));
    if (with_utc && d.utc_ns.size() != n)
        throw std::invalid_argument(fmt::format("{}: utc has {} rows, t_s has {}", path.string(), d.utc_ns.size(), n));
    const bool with_channels = !channels.empty();
    if (with_channels) {
        if (d.channel_values.size() != channels.size() || d.channel_quality.size() != channels.size())
            throw std::invalid_argument(fmt::format("{}: trial data has {} recorded channels, the campaign {}", path.string(),
                                                    d.channel_values.size(), channels.size()));
        for (std::size_t k = 0; k < channels.size(); ++k)
            if (d.channel_values[k].size() != n || d.channel_quality[k].size() != n)
                throw std::invalid_argument(fmt::format("{}: channel {} has {} rows, t_s has {}", path.string(),
                                                        channels[k].column(), d.channel_values[k].size(), n));
    }

    std::unique_ptr<std::FILE, WrittenFileCloser> f(std::fopen(path.c_str(), "wb"));
    if (!f) throw InputError(path.string(), 0, 0, "", fmt::format("cannot write: {}", std::strerror(errno)));
    std::string out = "t_s";
    if (with_utc) out += ",utc";
    const auto names = trial_csv_columns(map, with_speed, with_wall);
    for (std::size_t i = 1; i < names.size(); ++i) out += ',' + names[i];  // names[0] is t_s
    for (const auto& ch : channels) out += fmt::format(",{0},{0}.q", ch.column());
    out += '\n';
    // Written in blocks so memory stays flat however long the trial.
    constexpr std::size_t kFlushBytes = 1 << 18;
    for (std::size_t r = 0; r < n; ++r) {
        append_number(out, d.t_s[r]);
        if (with_utc) out += ',' + iso_utc_ms(d.utc_ns[r]);
        for (const auto* c : cols) {
            out += ',';
            append_number(out, (*c)[r]);
        }
        for (std::size_t k = 0; with_channels && k < channels.size(); ++k) {
            out += ',';
            append_number(out, d.channel_values[k][r]);
            out += ',';
            if (const auto q = d.channel_quality[k][r]; q != kNoSample) out += std::to_string(q);
        }
        out += '\n';
        if (out.size() >= kFlushBytes) {
            std::fwrite(out.data(), 1, out.size(), f.get());
            out.clear();
        }
    }
    std::fwrite(out.data(), 1, out.size(), f.get());
    if (std::fflush(f.get()) != 0 || std::ferror(f.get()) || std::fclose(f.release()) != 0)
        throw InputError(path.string(), 0, 0, "", fmt::format("write failed: {}", std::strerror(errno)));
}

}  // namespace

nlohmann::json ensembles_json(const std::map<std::string, Ensemble>& ensembles) {
    nlohmann::json out = nlohmann::json::object();
    for (const auto& [id, e] : ensembles) {
        out[id] = {{"description", e.description}};
        if (e.fcl) out[id]["fcl"] = *e.fcl;
        if (e.fcl_u) out[id]["fcl_u"] = *e.fcl_u;
    }
    return out;
}

bool is_note_kind(std::string_view kind) {
    return kind == "comment" || kind == "operator" || kind == "ensemble" || kind == "garment";
}

nlohmann::json notes_json(const std::vector<Note>& notes) {
    nlohmann::json out = nlohmann::json::array();
    for (const auto& n : notes) {
        nlohmann::json e{{"utc", iso_utc_ms(n.utc_ns)}, {"author", n.author}, {"kind", n.kind}, {"text", n.text}};
        if (!n.trial.empty()) e["trial"] = n.trial;
        out.push_back(std::move(e));
    }
    return out;
}

void write_trial_file(const std::filesystem::path& folder, const Campaign& campaign, const TrialInfo& info, const TrialData& data) {
    const std::filesystem::path csv = folder / (info.file.empty() ? "trials/" + info.id + ".csv" : info.file);
    std::filesystem::create_directories(csv.parent_path());
    write_trial_csv(csv, campaign.zone_map, campaign.channels, data);
}

void write_campaign_json(const std::filesystem::path& folder, const Campaign& campaign) {
    using nlohmann::json;
    std::filesystem::create_directories(folder);
    json doc;
    doc["format"] = kRecordingFormat;
    doc["name"] = campaign.name;
    if (campaign.zone_map_inline || campaign.zone_map.name != "andi35") {
        json zones = json::array();
        for (const auto& z : campaign.zone_map.zones) {
            zones.push_back({{"zone", z.zone}, {"name", z.name}, {"region", z.region}, {"segment", z.segment},
                             {"side", z.side}, {"area_m2", z.area_m2}, {"centroid_height_m", z.centroid_height_m}});
            if (!z.facing.empty()) zones.back()["facing"] = z.facing;
        }
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
    doc["heat_flux_sign"] = kHeatFluxSign;
    if (!campaign.channels.empty()) {
        json channels = json::array();
        for (const auto& ch : campaign.channels)
            channels.push_back({{"column", ch.column()}, {"device", ch.device}, {"channel", ch.name}, {"unit", ch.unit}});
        doc["channels"] = channels;
    }
    if (!campaign.provenance.empty()) doc["provenance"] = campaign.provenance;
    if (!campaign.ensembles.empty()) doc["ensembles"] = ensembles_json(campaign.ensembles);
    if (!campaign.standards.empty()) doc["standards"] = campaign.standards;
    if (!campaign.notes.empty()) doc["notes"] = notes_json(campaign.notes);
    json trials = json::array();
    for (const auto& t : campaign.trials) {
        const auto& i = t.info;
        const std::string file = i.file.empty() ? "trials/" + i.id + ".csv" : i.file;
        json e{{"id", i.id}, {"case", i.case_id}, {"replicate", i.replicate}, {"file", file}};
        if (i.skin_setpoint_c) e["skin_setpoint_c"] = *i.skin_setpoint_c;
        if (!i.ensemble.empty()) e["ensemble"] = i.ensemble;
        if (!i.test.empty()) e["test"] = i.test;
        if (!i.control.empty()) e["control"] = i.control;
        if (const auto room = local_room_json(campaign.zone_map, i.local); !room.empty()) e["local"] = room;
        if (i.partial) e["partial"] = true;
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
        if (i.t0_utc_ns) e["t0_utc"] = iso_utc_ms(*i.t0_utc_ns);
        trials.push_back(e);
    }
    doc["trials"] = trials;
    // Every byte checked: a full disk is an error here, not a campaign.json cut short.
    const auto json_path = folder / "campaign.json";
    std::FILE* out = std::fopen(json_path.c_str(), "wb");
    if (!out) throw InputError(json_path.string(), 0, 0, "", fmt::format("cannot write: {}", std::strerror(errno)));
    const std::string text = doc.dump(2, ' ', false, json::error_handler_t::replace) + '\n';
    const bool written = std::fwrite(text.data(), 1, text.size(), out) == text.size() && std::fflush(out) == 0;
    const int err = errno;
    if (std::fclose(out) != 0 || !written)
        throw InputError(json_path.string(), 0, 0, "", fmt::format("write failed: {}", std::strerror(written ? errno : err)));
}

void write_campaign(const std::filesystem::path& folder, const Campaign& campaign) {
    std::filesystem::create_directories(folder / "trials");
    for (const auto& t : campaign.trials) write_trial_file(folder, campaign, t.info, t.data);
    write_campaign_json(folder, campaign);
}

}  // namespace manikind::analysis
