#include "store/database_export.hpp"

#include <set>
#include <fmt/format.h>
#include <nlohmann/json.hpp>

#include <algorithm>
#include <cmath>
#include <ctime>
#include <limits>
#include <map>
#include <optional>

#include "analysis/zone_map.hpp"
#include "base/user_error.hpp"

namespace manikind {

namespace {

std::string iso_utc(std::int64_t utc_ns) {
    const std::time_t t = static_cast<std::time_t>(utc_ns / 1000000000);
    std::tm tm{};
    gmtime_r(&t, &tm);
    char buf[32];
    std::strftime(buf, sizeof buf, "%Y-%m-%dT%H:%M:%SZ", &tm);
    return buf;
}

using recorder::BinnedChannel;
using recorder::ChannelBinner;

constexpr std::size_t kNoChannel = static_cast<std::size_t>(-1);

// Good values only, for the analysis columns (a flagged reading never enters a mean).
std::vector<double> good_values(const BinnedChannel& c) {
    std::vector<double> out = c.value;
    for (std::size_t i = 0; i < out.size(); ++i)
        if (c.quality[i] != 0) out[i] = std::numeric_limits<double>::quiet_NaN();
    return out;
}

std::vector<double> mean_of(const std::vector<const BinnedChannel*>& series, std::size_t n) {
    std::vector<double> out(n, std::numeric_limits<double>::quiet_NaN());
    for (std::size_t i = 0; i < n; ++i) {
        double s = 0;
        int k = 0;
        for (const auto* c : series)
            if (c->quality[i] == 0 && std::isfinite(c->value[i])) s += c->value[i], ++k;
        if (k) out[i] = s / k;
    }
    return out;
}

}  // namespace

int case_number_of(const recorder::CaseRow& c) {
    const auto j = nlohmann::json::parse(c.conditions_json, nullptr, false);
    const int by_position = static_cast<int>(c.position + 1);
    return j.is_object() && j.contains("id") && j["id"].is_number_integer() ? j["id"].get<int>() : by_position;
}

std::string exported_trial_id(int case_number, std::int64_t replicate) { return fmt::format("c{:02d}-r{}", case_number, replicate); }

std::map<std::int64_t, std::string> exported_trial_ids(recorder::Database& db, std::int64_t campaign_id) {
    std::map<std::int64_t, int> case_number;
    for (const auto& c : db.cases(campaign_id)) case_number[c.id] = case_number_of(c);
    std::map<std::int64_t, std::string> out;
    for (const auto& t : db.trials(campaign_id)) out[t.id] = exported_trial_id(case_number[t.case_id], t.replicate);
    return out;
}

struct CampaignReader::Span {
    recorder::TrialRow row;
    std::int64_t start_mono_ns, end_mono_ns, start_utc_ns;
};

CampaignReader::CampaignReader(recorder::Database& db, const std::string& name, double period_s, bool include_running)
    : db_(db), period_s_(period_s) {
    const auto campaign_id = db.find_campaign(name);
    if (!campaign_id) throw UserError(fmt::format("{}: no campaign named '{}'", db.path().string(), name));
    auto& c = campaign_;
    c.name = name;
    c.zone_map = analysis::andi35_zone_map();
    c.zone_map_inline = true;  // the export names every zone with its area and region, not only "andi35"
    c.instruments = analysis::default_instrument_specs();
    // Clothing campaigns: the ensembles of the campaign's definition (docs/clothing.md).
    for (const auto& row : db.campaigns())
        if (row.id == *campaign_id) {
            const auto def = nlohmann::json::parse(row.definition_json, nullptr, false);
            if (def.is_object() && def.contains("ensembles") && def.at("ensembles").is_object())
                for (const auto& [id, e] : def.at("ensembles").items()) {
                    analysis::Ensemble ens;
                    if (e.is_object() && e.contains("description") && e.at("description").is_string())
                        ens.description = e.at("description").get<std::string>();
                    if (e.is_object() && e.contains("fcl") && e.at("fcl").is_number()) ens.fcl = e.at("fcl").get<double>();
                    if (e.is_object() && e.contains("fcl_u") && e.at("fcl_u").is_number()) ens.fcl_u = e.at("fcl_u").get<double>();
                    c.ensembles[id] = ens;
                }
            if (def.is_object() && def.contains("standards") && def.at("standards").is_object())
                for (const auto& [test, standard] : def.at("standards").items())
                    if (standard.is_string()) c.standards[test] = standard.get<std::string>();
        }
    std::map<std::int64_t, nlohmann::json> conditions;
    std::map<std::int64_t, int> case_number;
    for (const auto& cs : db.cases(campaign_id.value())) {
        conditions[cs.id] = nlohmann::json::parse(cs.conditions_json, nullptr, false);
        if (!conditions[cs.id].is_object()) conditions[cs.id] = nlohmann::json::object();  // read as "nothing said"
        case_number[cs.id] = case_number_of(cs);
    }
    all_channels_ = db.channels();

    // The finished trials and their time bases (the manikin's start to the trial's end).
    for (const auto& t : db.trials(campaign_id.value())) {
        const bool running = include_running && !recorder::is_terminal_trial_state(t.state) && t.state != "pending";
        if (t.state != "done" && !running) continue;
        std::optional<recorder::EventRow> start, end;
        for (const auto& e : db.events(t.id)) {
            if (e.kind == "stage" && e.message == "acquiring") start = e;
            if (e.kind == "stage" && e.message == "stopping") end = e;
        }
        bool partial = false;
        if (running && start && !end) {
            // Up to the last reading committed now: what a reader of the file sees is all there is.
            const auto last = db.last_sample_mono_ns(t.id);
            if (!last || *last <= start->mono_ns) continue;
            spans_.push_back({t, start->mono_ns, *last, start->utc_ns});
            partial = true;
        } else {
            if (!start || !end || end->mono_ns <= start->mono_ns) continue;
            spans_.push_back({t, start->mono_ns, end->mono_ns, start->utc_ns});
        }
        const auto& sp = spans_.back();
        analysis::Trial trial;
        const nlohmann::json& cond = conditions[sp.row.case_id];
        trial.info.case_id = case_number[sp.row.case_id];
        trial.info.replicate = static_cast<int>(sp.row.replicate);
        trial.info.id = exported_trial_id(trial.info.case_id, sp.row.replicate);
        trial.info.file = "trials/" + trial.info.id + ".csv";
        trial.info.skin_setpoint_c = cond.value("skin_setpoint_c", 35.0);
        trial.info.wettedness = cond.value("wet", false) ? 1.0 : 0.0;
        trial.info.ensemble = cond.value("ensemble", "");
        trial.info.test = cond.value("test", "");
        trial.info.control = cond.value("control", "");
        if (cond.contains("local")) {  // the room the plan stated for the case ([[cases.local]])
            std::string why;
            trial.info.local = analysis::parse_local_room(c.zone_map, cond.at("local"), why);
            if (!why.empty())
                throw UserError(fmt::format("{}: case {}: its stored room (local{}) cannot be read", db.path().string(),
                                            trial.info.case_id, why));
        }
        if (trial.info.control == "physiological") trial.info.skin_setpoint_c.reset();  // the model's, zone by zone
        trial.info.chamber_setpoint_temp_c = cond.value("chamber_temp_c", 0.0);
        trial.info.chamber_setpoint_rh_pct = cond.value("chamber_rh_pct", 0.0);
        trial.info.started_utc = sp.row.started_utc_ns ? iso_utc(*sp.row.started_utc_ns) : "";
        trial.info.t0_utc_ns = sp.start_utc_ns;
        trial.info.partial = partial;
        c.trials.push_back(std::move(trial));
    }
    if (spans_.empty())
        throw UserError(fmt::format("campaign '{}' has no finished trial yet{}", name,
                                    include_running ? " and none acquiring" : " (manikin export takes a running one too)"));

    // Channel id -> index into all_channels_, looked up once per sample: a vector by id (ids are
    // SQLite rowids from 1, one per channel, so it stays small), not a map.
    for (std::size_t k = 0; k < all_channels_.size(); ++k) {
        const auto id = static_cast<std::size_t>(std::max<std::int64_t>(all_channels_[k].id, 0));
        if (id >= index_of_id_.size()) index_of_id_.resize(id + 1, kNoChannel);
        index_of_id_[id] = k;
    }
    recorded_.assign(all_channels_.size(), false);
    for (std::size_t k = 0; k < all_channels_.size(); ++k) index_of_key_[all_channels_[k].device_name + "/" + all_channels_[k].name] = k;

    // The lab notebook: every note of the campaign; one about a trial names it by its exported id
    // (a trial not exported, one that did not finish, keeps its note on the campaign, saying so).
    std::map<std::int64_t, std::string> exported_id;
    for (std::size_t s = 0; s < spans_.size(); ++s) exported_id[spans_[s].row.id] = c.trials[s].info.id;
    for (const auto& n : db.notes(campaign_id.value())) {
        analysis::Note note{n.utc_ns, n.author, n.kind, n.text, {}};
        if (n.trial_id) {
            if (const auto it = exported_id.find(*n.trial_id); it != exported_id.end()) note.trial = it->second;
            else note.text = fmt::format("(about trial {}, not exported) {}", *n.trial_id, n.text);
        }
        c.notes.push_back(std::move(note));
    }

    // Provenance: what made these numbers.
    c.provenance["program"] = std::string("manikind ") + MANIKIND_VERSION;
    c.provenance["database"] = db.path().filename().string();
    c.provenance["twin_version"] = db.latest_twin_version().value_or("baseline");
    const std::int64_t first_start_utc_ns = spans_.front().start_utc_ns;
    std::int64_t config_utc_ns = 0;  // the configuration the daemon ran under at the first trial
    for (const auto& e : db.events(std::nullopt))
        if (e.kind == "config" && e.utc_ns <= first_start_utc_ns && e.utc_ns >= config_utc_ns && e.message.starts_with("sha256 ")) {
            c.provenance["config_sha256"] = e.message.substr(7, 64);
            config_utc_ns = e.utc_ns;
        }
}

CampaignReader::~CampaignReader() = default;

std::size_t CampaignReader::trial_count() const { return spans_.size(); }

const recorder::TrialBins* CampaignReader::usable_bins(std::size_t i) {
    const auto& sp = spans_.at(i);
    const auto it = recorded_bins_.find(sp.row.id);
    if (it == recorded_bins_.end() || !it->second) return nullptr;
    const recorder::TrialBins& b = *it->second;
    if (!b.usable() || b.period_s() != period_s_ || b.t0_mono_ns() != sp.start_mono_ns) return nullptr;
    // Every row offered was stored once: none lost, none skipped as a re-sent duplicate.
    if (static_cast<std::int64_t>(b.rows()) != db_.sample_count(sp.row.id)) return nullptr;
    return &b;
}

analysis::TrialData CampaignReader::read(std::size_t s) {
    const auto& sp = spans_.at(s);
    const double period_s = period_s_;
    const auto n = static_cast<std::size_t>(std::floor(static_cast<double>(sp.end_mono_ns - sp.start_mono_ns) * 1e-9 / period_s)) + 1;
    std::vector<BinnedChannel> bins;
    bins.reserve(all_channels_.size());
    std::vector<bool> any(all_channels_.size(), false);
    if (const auto* live = usable_bins(s)) {
        // Binned as recorded (TrialBins): the same arithmetic on the same rows, not read back.
        for (std::size_t k = 0; k < all_channels_.size(); ++k) {
            any[k] = live->any_sample(all_channels_[k].id);
            bins.push_back(live->binned(all_channels_[k].id, n));
        }
        ++from_recording_;
        // Read once: memory goes down as the campaign is built (a trial read again, because a
        // later one added a channel, is read from the database).
        recorded_bins_.erase(sp.row.id);
    } else {
        std::vector<ChannelBinner> binners(all_channels_.size(), ChannelBinner(sp.start_mono_ns, period_s, n));
        db_.for_each_trial_sample(sp.row.id, [&](const recorder::SampleRow& r) {
            const auto id = static_cast<std::size_t>(r.channel_id);
            if (r.channel_id >= 0 && id < index_of_id_.size() && index_of_id_[id] != kNoChannel) binners[index_of_id_[id]].add(r);
        });
        for (std::size_t k = 0; k < all_channels_.size(); ++k) {
            any[k] = binners[k].any_sample();
            bins.push_back(binners[k].finish(n));
        }
    }
    // Every channel with samples in any trial read so far gets a column in every trial (a fixed
    // set once all are read, so a script reads each trial alike); one first seen here is added
    // in the database's order of channels.
    bool grew = false;
    for (std::size_t k = 0; k < all_channels_.size(); ++k)
        if (any[k] && !recorded_[k]) recorded_[k] = grew = true;
    if (grew) {
        ++generation_;
        campaign_.channels.clear();
        for (std::size_t k = 0; k < all_channels_.size(); ++k)
            if (recorded_[k]) campaign_.channels.push_back({all_channels_[k].device_name, all_channels_[k].name, all_channels_[k].unit});
    }
    const auto find = [&](const std::string& key) -> const BinnedChannel* {
        const auto it = index_of_key_.find(key);
        return it == index_of_key_.end() || !recorded_[it->second] ? nullptr : &bins[it->second];
    };
    analysis::TrialData d;
    for (std::size_t i = 0; i < n; ++i) {
        d.t_s.push_back(static_cast<double>(i) * period_s);
        d.utc_ns.push_back(sp.start_utc_ns + static_cast<std::int64_t>(std::llround(static_cast<double>(i) * period_s * 1e9)));
    }
    // The analysis columns: air and wall as the mean of their instruments (Text S3.2).
    std::vector<const BinnedChannel*> temps, rhs, walls;
    for (int k = 1; k <= 8; ++k) {
        if (const auto* b = find(fmt::format("datalogger/ee181_{}.air_temp_c", k))) temps.push_back(b);
        if (const auto* b = find(fmt::format("datalogger/ee181_{}.air_rh_pct", k))) rhs.push_back(b);
        if (const auto* b = find(fmt::format("datalogger/wall_tc_{}.wall_temp_c", k))) walls.push_back(b);
    }
    d.air_temp_c = mean_of(temps, n);
    d.air_rh_pct = mean_of(rhs, n);
    if (!walls.empty()) d.wall_temp_c = mean_of(walls, n);
    if (const auto* b = find("windsonic/air_speed_m_s")) d.air_speed_m_s = good_values(*b);
    const std::vector<double> missing(n, std::numeric_limits<double>::quiet_NaN());
    for (const auto& z : campaign_.zone_map.zones) {
        const auto* skin = find(fmt::format("manikin/z{:02d}.skin_temp_c", z.zone));
        const auto* flux = find(fmt::format("manikin/z{:02d}.heat_flux_w_m2", z.zone));
        d.skin_temp_c.push_back(skin ? good_values(*skin) : missing);
        d.heat_flux_w_m2.push_back(flux ? good_values(*flux) : missing);
    }
    for (std::size_t k = 0; k < all_channels_.size(); ++k)
        if (recorded_[k]) {
            d.channel_values.push_back(std::move(bins[k].value));
            d.channel_quality.push_back(std::move(bins[k].quality));
        }
    return d;
}

ExportCounts stream_trials(CampaignReader& reader, const TrialVisitor& visit, const ExportProgress& progress) {
    ExportCounts counts;
    std::vector<std::size_t> generation(reader.trial_count());
    for (std::size_t s = 0; s < reader.trial_count(); ++s) {
        auto data = reader.read(s);
        generation[s] = reader.channel_generation();
        counts.rows += data.rows();
        counts.last_t_s.push_back(data.t_s.empty() ? 0.0 : data.t_s.back());
        visit(s, std::move(data), false);
        if (progress) progress(s + 1, reader.trial_count());
    }
    // A trial read before a later one added a channel is read again with the final set.
    for (std::size_t s = 0; s < reader.trial_count(); ++s)
        if (generation[s] != reader.channel_generation()) {
            visit(s, reader.read(s), true);
            ++counts.rewritten;
        }
    return counts;
}

analysis::Campaign campaign_from_database(recorder::Database& db, const std::string& name, double period_s, bool include_running) {
    CampaignReader reader(db, name, period_s, include_running);
    return read_whole_campaign(reader);
}

analysis::Campaign read_whole_campaign(CampaignReader& reader) {
    std::vector<analysis::TrialData> data(reader.trial_count());
    stream_trials(reader, [&](std::size_t s, analysis::TrialData&& d, bool) { data[s] = std::move(d); });
    analysis::Campaign c = reader.campaign();
    for (std::size_t s = 0; s < c.trials.size(); ++s) c.trials[s].data = std::move(data[s]);
    return c;
}

void export_campaign(recorder::Database& db, const std::string& name, const std::filesystem::path& folder) {
    CampaignReader reader(db, name);
    export_campaign_csv(reader, folder);
}

ExportCounts export_campaign_csv(CampaignReader& reader, const std::filesystem::path& folder, const ExportProgress& progress) {
    const auto counts = stream_trials(
        reader,
        [&](std::size_t s, analysis::TrialData&& data, bool) {
            analysis::write_trial_file(folder, reader.campaign(), reader.campaign().trials[s].info, data);
        },
        progress);
    analysis::write_campaign_json(folder, reader.campaign());
    return counts;
}

}  // namespace manikind
