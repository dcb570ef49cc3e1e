// LabDaemon's campaign runner: starting a plan (and resuming one a restart interrupted), pause,
// resume and abort, the results after each trial and at the end, and reading them back.
// The rest of LabDaemon: lab_daemon.cpp.
#include "daemon/lab_daemon.hpp"

#include <fmt/format.h>
#include <spdlog/spdlog.h>

#include <algorithm>
#include <set>

#include "analysis/analyze.hpp"
#include "analysis/clothing.hpp"
#include "analysis/physio.hpp"
#include "analysis/recording.hpp"
#include "store/database_export.hpp"
#include "analysis/reconcile/results_parity.hpp"
#include "base/text.hpp"
#include "base/user_error.hpp"

namespace manikind {

namespace {
// The grid the campaign's results read the recordings on (CampaignReader's default: Text S3.2).
constexpr double kExportPeriod_s = 5.0;
}  // namespace

std::string LabDaemon::start_campaign(const CampaignPlan& plan) {
    // One gate for every plan, whatever brought it: a name with a NUL or a line break (the API's
    // built-in plan took any) broke every later archive push of the database (issue 60).
    if (const auto why = plan_text_problem(plan); !why.empty()) return why;
    std::lock_guard lk(lock_);
    if (const auto why = check_plan_against_limits(plan, o_.config.safety); !why.empty()) return why;
    if (const auto why = check_plan_against_devices(plan, o_.config); !why.empty()) return why;
    if (storage_full_)
        return fmt::format("the disk holding {} is full ({}); free space first, recording resumes by itself",
                           db_path_.string(), storage_error_);
    if ((plan_ && plan_->name == plan.name) ||
        std::any_of(waiting_.begin(), waiting_.end(), [&](const CampaignPlan& p) { return p.name == plan.name; }))
        return fmt::format("a campaign named '{}' is already running or queued", plan.name);
    // What the daemon reads back must include every write it made: the recorder makes them first.
    if (!flush_all_locked()) {
        watch_storage_locked();
        return fmt::format("the database {} cannot be written now ({}); the daemon's writes wait in order; start the "
                           "campaign again when the alarm clears",
                           db_path_.string(), recorder_->stats().storage_error);
    }
    // One already in the database is continued, if it is the same plan and not complete.
    if (const auto existing = db_.find_campaign(plan.name)) {
        const auto campaigns = db_.campaigns();
        const auto row = std::find_if(campaigns.begin(), campaigns.end(), [&](const auto& c) { return c.id == *existing; });
        // "done" with a failed trial (a device gave up for good) is not complete: it continues too.
        std::set<std::pair<std::int64_t, std::int64_t>> done_trials;
        for (const auto& t : db_.trials(*existing))
            if (t.state == "done") done_trials.insert({t.case_id, t.replicate});
        if (row->state == "done" && done_trials.size() >= static_cast<std::size_t>(plan.replicates) * plan.cases.size())
            return fmt::format("campaign '{}' is complete in {}; give the plan a new name to run it again", plan.name,
                               db_path_.string());
        std::vector<nlohmann::json> stored_cases;
        for (const auto& c : db_.cases(*existing))
            stored_cases.push_back(nlohmann::json::parse(c.conditions_json, nullptr, false));
        const auto differences =
            plan_differences(plan, nlohmann::json::parse(row->definition_json, nullptr, false), stored_cases);
        if (!differences.empty()) {
            std::string list;
            for (const auto& d : differences) list += "\n  " + d;
            return fmt::format("campaign '{}' in {} was planned differently; continue it with the same plan, or give "
                               "this one a new name. Differences:{}",
                               plan.name, db_path_.string(), list);
        }
    }
    if (plan_) {
        waiting_.push_back(plan);
        event("info", "campaign", fmt::format("'{}' queued behind '{}' ({} waiting)", plan.name, plan_->name, waiting_.size()));
        return {};
    }
    try {
        begin_campaign(plan);
    } catch (const recorder::StorageBusy& e) {
        return fmt::format("the database is locked ({}); start the campaign again when the alarm clears", e.what());
    } catch (const recorder::StorageFull& e) {
        return fmt::format("the disk is full ({}); start the campaign again when space is freed", e.what());
    } catch (const recorder::StorageFault& e) {
        return fmt::format("the file system fails ({}); start the campaign again when the alarm clears", e.what());
    }
    return {};
}

// Throws StorageBusy/Full/Fault, having changed nothing, when the campaign cannot be written now.
void LabDaemon::begin_campaign(const CampaignPlan& plan) {
    std::vector<std::pair<PlannedCase, std::int64_t>> cases;
    std::set<std::pair<std::int64_t, std::int64_t>> done;  // (case row, replicate) finished before
    const auto existing = db_.find_campaign(plan.name);
    std::int64_t campaign_id = 0;
    if (existing) {
        // Continuing (start_campaign checked it is the same plan): finished trials are kept; an
        // interrupted, aborted or failed one stays in the database with its reason (the analysis
        // reads done trials only) and is run again.
        campaign_id = *existing;
        const auto stored = db_.cases(campaign_id);
        for (std::size_t i = 0; i < plan.cases.size() && i < stored.size(); ++i) cases.emplace_back(plan.cases[i], stored[i].id);
        for (const auto& t : db_.trials(campaign_id))
            if (t.state == "done") done.insert({t.case_id, t.replicate});
        recorder_->call([&](recorder::Database& db) { db.set_campaign_state(campaign_id, "running"); });
    } else {
        // One call: the campaign and its cases are made together, or (storage waiting) not at all.
        std::vector<std::int64_t> case_ids;
        campaign_id = recorder_->call([&](recorder::Database& db) {
            std::int64_t id = 0;
            case_ids.clear();
            db.atomically([&] {
                id = db.create_campaign(plan.name, campaign_definition_json(plan).dump());
                int position = 0;
                for (const auto& c : plan.cases)
                    case_ids.push_back(db.add_case(id, fmt::format("case {}", c.id), case_conditions_json(c).dump(), position++));
                db.set_campaign_state(id, "running");
            });
            return id;
        });
        for (std::size_t i = 0; i < plan.cases.size(); ++i) cases.emplace_back(plan.cases[i], case_ids.at(i));
    }
    campaign_id_ = campaign_id;
    queue_.clear();
    for (int r = 1; r <= plan.replicates; ++r)
        for (const auto& [c, id] : cases)
            if (!done.count({id, r})) queue_.push_back({c, id, r});
    trials_total_ = plan.replicates * static_cast<int>(cases.size());
    trials_done_ = static_cast<int>(done.size());
    plan_ = plan;
    safety_tripped_ = false;
    last_campaign_ = plan.name;
    if (existing)
        event("info", "campaign", fmt::format("'{}' continued: {} of {} trials done before, {} to run", plan.name,
                                              trials_done_, trials_total_, queue_.size()));
    else
        event("info", "campaign",
              fmt::format("'{}' started: {} cases x {} replicates", plan.name, plan.cases.size(), plan.replicates));
}

std::string LabDaemon::abort(const std::string& reason, const std::string& who) {
    std::lock_guard lk(lock_);
    if (!plan_) return "no campaign is running";
    acq_->manikin().set_run(false);
    event("warn", "abort", fmt::format("'{}' aborted by {}: {}", plan_->name, who, reason));
    if (trial_id_) finish_trial("aborted", fmt::format("{} (by {})", reason, who));
    if (operator_prompt_) {  // nobody waits for the operator any more
        alarms_.clear("operator", "prompt", "the campaign was aborted", now_utc_ns());
        operator_prompt_.reset();
    }
    waiting_.clear();  // an operator's abort stops what was queued too
    finish_campaign("aborted");
    return {};
}

std::string LabDaemon::operator_continue(const std::string& who) {
    std::lock_guard lk(lock_);
    if (!operator_prompt_) return "nothing is waiting for the operator";
    const std::string message = fmt::format("done: {} (said by {})", *operator_prompt_, printable(who, 100));
    event("info", "operator", message);
    alarms_.clear("operator", "prompt", message, now_utc_ns());
    operator_prompt_.reset();
    operator_answered_ = true;  // the next tick's configuring goes on
    return {};
}

std::string LabDaemon::pause() {
    std::lock_guard lk(lock_);
    if (!plan_) return "no campaign is running";
    if (paused_) return "already paused";
    paused_ = true;
    paused_at_ns_ = clock_->mono_ns();
    event("info", "campaign", "paused");
    return {};
}

std::string LabDaemon::resume() {
    std::lock_guard lk(lock_);
    if (!paused_) return "not paused";
    const std::int64_t paused_ns = clock_->mono_ns() - paused_at_ns_;
    stage_start_ns_ += paused_ns;   // the stage's clock stood still
    paused_total_ns_ += paused_ns;  // and a physiological model's with it
    paused_ = false;
    event("info", "campaign", "resumed");
    return {};
}

void LabDaemon::begin_trial_bins_locked(std::int64_t trial_id) {
    current_bins_ = nullptr;
    if (!o_.virtual_clock) return;  // a trial a day: reading it back costs nothing worth keeping it for
    if (recorded_bins_.empty()) {
        const auto rs = recorder_->stats();
        recorder_losses_at_start_ = rs.duplicates + rs.dropped + rs.lost;
    }
    // Sealed, a trial's bins are a value and a quality per channel and 5-s row (1.2 MB for the
    // simulated lab's 75-min trial); past this budget the later trials are read back instead.
    constexpr std::size_t kBudgetBytes = std::size_t{256} << 20;
    std::size_t held = 0;
    for (const auto& [id, b] : recorded_bins_) held += b->bytes();
    if (held >= kBudgetBytes) return;
    auto bins = std::make_shared<recorder::TrialBins>(kExportPeriod_s);
    current_bins_ = bins.get();
    recorded_bins_[trial_id] = std::move(bins);
}

// Results so far, after each trial in real time (a lab waits 75 min per trial; the console shows
// each case's flux and the parity plot as they come). On its own thread and database connection:
// the tick and the safety checks never wait for an analysis. On the virtual clock only the final
// results are computed (a demo would spend its time re-analysing).
void LabDaemon::start_interim_results() {
    if (interim_thread_.joinable()) {
        if (!interim_done_) return;  // the previous one is still running: the next trial will catch up
        interim_thread_.join();
    }
    interim_done_ = false;
    interim_thread_ = std::thread([this, name = plan_->name, campaign_id = campaign_id_, utc = clock_->utc_ns()] {
        try {
            // Read back after the recorder has made every write so far (the trial just done);
            // read-only: the recorder stays the one writer and stores the result.
            if (!recorder_->flush()) throw UserError("the database cannot be written now; the next trial's results will catch up");
            auto db = recorder::Database::open_read_only(db_path_);
            const auto result = analysis::analyze_campaign(campaign_from_database(db, name));
            auto j = analysis::to_json(result);
            j["interim"] = true;
            j["twin_parity"] = twin_parity_json(result);
            recorder_->post([campaign_id, text = j.dump(), utc](recorder::Database& w) { w.store_result(campaign_id, text, utc); });
        } catch (const std::exception& e) {
            spdlog::warn("interim results for '{}': {}", name, e.what());
        } catch (...) {
            spdlog::warn("interim results for '{}': an exception that is not a std::exception", name);
        }
        interim_done_ = true;
    });
}

void LabDaemon::flush_recorder() {
    std::lock_guard lk(lock_);
    flush_all_locked();
}

void LabDaemon::finish_campaign(const std::string& state) {
    // The results read every trial back: the recorder makes the writes waiting first. While it
    // cannot (locked, full, failing), the campaign stays open and the next tick tries again.
    if (state == "done" && !flush_all_locked()) {
        watch_storage_locked();
        return;
    }
    queue_.clear();
    if (state == "done") {
        stage_ = Stage::computing;
        try {
            // The trials binned as recorded, unless the recorder skipped, dropped or lost a reading
            // since the campaign began (then each trial is read back from the database).
            CampaignReader::RecordedBins bins;
            const auto rs = recorder_->stats();
            if (rs.duplicates + rs.dropped + rs.lost == recorder_losses_at_start_)
                for (auto& [id, b] : recorded_bins_) bins.emplace(id, std::move(b));  // freed as the reader goes
            CampaignReader reader(db_, plan_->name, kExportPeriod_s);
            reader.use_recorded_bins(std::move(bins));
            const auto read = std::make_shared<const analysis::Campaign>(read_whole_campaign(reader));
            trials_binned_as_recorded_ = reader.trials_from_recording();
            const analysis::Campaign& campaign = *read;
            if (o_.virtual_clock) computed_campaign_ = read;
            const auto result = analysis::analyze_campaign(campaign);
            auto j = analysis::to_json(result);
            j["interim"] = false;
            j["twin_parity"] = twin_parity_json(result);
            // Physiological trials: their trajectories (no steady state), a point a minute.
            analysis::physio::Options few;
            few.draws = 50;
            if (const auto physio = analysis::physio::compute(campaign, few); !physio.trials.empty())
                j["physiological"] = analysis::physio::results_json(physio);
            // Clothing tests: clo and Ret per ensemble, as `manikin clothing` gives them (the
            // standards' stop rule; fewer Monte Carlo draws: the full run is the command's).
            if (std::any_of(campaign.trials.begin(), campaign.trials.end(), [](const auto& t) { return !t.info.test.empty(); })) {
                analysis::AnalysisOptions standard;
                standard.steady.require_heat_loss_stability = true;
                analysis::clothing::Options co;
                co.monte_carlo_draws = 500;
                try {
                    j["clothing"] = analysis::clothing::to_json(
                        analysis::clothing::compute(campaign, analysis::analyze_campaign(campaign, standard), nullptr, nullptr, co));
                } catch (const std::invalid_argument& e) {
                    event("warn", "results", std::string("clothing results: ") + e.what());
                }
            }
            write([=, campaign = campaign_id_, text = j.dump(), utc_ns = clock_->utc_ns()](recorder::Database& db) {
                db.store_result(campaign, text, utc_ns);
            });
            event("info", "results", fmt::format("'{}': results stored", plan_->name));
        } catch (const std::exception& e) {
            event("error", "results", std::string("could not compute results: ") + e.what());
        }
    }
    recorded_bins_.clear();
    current_bins_ = nullptr;
    write([=, campaign = campaign_id_](recorder::Database& db) { db.set_campaign_state(campaign, state); });
    event("info", "campaign", fmt::format("'{}' {}", plan_->name, state));
    {
        std::string body;
        // This campaign's trials: the last trials_total_ summaries (a daemon may have run others before).
        const std::size_t n = std::min<std::size_t>(trial_summaries_.size(), static_cast<std::size_t>(std::max(0, trials_total_)));
        for (std::size_t i = trial_summaries_.size() - n; i < trial_summaries_.size(); ++i) body += trial_summaries_[i] + "\n";
        notify_locked("campaign_end", state == "done" ? "info" : "warn", fmt::format("campaign '{}' {}", plan_->name, state), body);
    }
    standby_locked(fmt::format("campaign '{}' {}", plan_->name, state));
    plan_.reset();
    paused_ = false;
    stage_ = Stage::idle;
    // The next campaign queued begins at the next tick (advance_locked).
}

// Heating off and the chamber at [standby], after a campaign ends or is aborted: the enclosure is
// not left at the last case's setpoint with nobody watching.
void LabDaemon::standby_locked(const std::string& why) {
    if (acq_) acq_->manikin().set_run(false);
    const auto& sb = o_.config.standby;
    if (const auto refused = set_chamber(sb.chamber_temp_c, sb.chamber_rh_pct); !refused.empty())
        event("warn", "standby", fmt::format("{}: the chamber could not be put in standby: {}", why, refused));
    else
        event("info", "standby", fmt::format("{}: heating off, chamber {} °C, {} %", why, sb.chamber_temp_c, sb.chamber_rh_pct));
}

std::optional<std::string> LabDaemon::running_campaign() {
    std::lock_guard lk(lock_);
    if (plan_) return plan_->name;
    return std::nullopt;
}

nlohmann::json LabDaemon::campaign_outcome_json(const std::string& campaign) {
    std::lock_guard lk(lock_);
    flush_all_locked();  // the last states written are read back
    const auto id = db_.find_campaign(campaign);
    if (!id) throw UserError(fmt::format("{}: no campaign named '{}'", db_path_.string(), campaign));
    std::string state;
    for (const auto& c : db_.campaigns())
        if (c.id == *id) state = c.state;
    const bool active = (plan_ && plan_->name == campaign) ||
                        std::any_of(waiting_.begin(), waiting_.end(), [&](const CampaignPlan& p) { return p.name == campaign; });
    std::map<std::string, int> by_state;
    std::set<std::pair<std::int64_t, std::int64_t>> done, tried;
    int fallbacks = 0;  // physiological trials that fell back to constant skin temperature
    for (const auto& t : db_.trials(*id)) {
        ++by_state[t.state];
        fallbacks += (t.quality_flags & flag_model_fallback) != 0 ? 1 : 0;
        tried.insert({t.case_id, t.replicate});
        if (t.state == "done") done.insert({t.case_id, t.replicate});
    }
    nlohmann::json trials = nlohmann::json::object();
    for (const auto& [s, n] : by_state) trials[s] = n;
    const std::size_t planned = db_.cases(*id).size();
    return {{"campaign", campaign},
            {"state", active ? std::string("running") : state},
            {"active", active},
            {"trials", trials},
            {"model_fallbacks", fallbacks},
            // Every case x replicate tried has a done trial (an interrupted one run again counts once),
            // and no physiological trial ran its end at constant skin temperature (issue 64).
            {"ok", !active && state == "done" && done.size() == tried.size() && planned > 0 && fallbacks == 0}};
}

bool LabDaemon::campaign_active() {
    std::lock_guard lk(lock_);
    return plan_.has_value() || !waiting_.empty();  // one queued begins at the next tick
}

std::optional<nlohmann::json> LabDaemon::latest_results_json(const std::string& campaign) {
    std::lock_guard lk(lock_);
    flush_all_locked();  // the results just stored are read back (storage waiting: the last ones made)
    const auto id = db_.find_campaign(campaign);
    if (!id) throw UserError(fmt::format("{}: no campaign named '{}'", db_path_.string(), campaign));
    const auto r = db_.latest_result(*id);
    if (!r) return std::nullopt;
    return nlohmann::json::parse(r->json);
}

nlohmann::json LabDaemon::results_json(const std::string& campaign) {
    auto r = latest_results_json(campaign);
    if (!r) throw UserError(fmt::format("campaign '{}' has no results yet", campaign));
    return std::move(*r);
}

}  // namespace manikind
