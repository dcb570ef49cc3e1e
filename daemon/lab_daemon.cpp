// LabDaemon (daemon/lab_daemon.hpp), in four files by what a reader looks for:
//   lab_daemon.cpp            construction and wiring, events, alarms, notes, the clocks (virtual and
//                             real time), stop, status and the live values;
//   lab_daemon_trial.cpp      the trial's stage machine, settling, steady state, safety stop;
//   lab_daemon_campaign.cpp   the campaign runner: start, resume, pause, abort, results;
//   lab_daemon_recording.cpp  the sample path to the recorder and the storage faults.
#include "daemon/lab_daemon.hpp"

#include <fmt/format.h>
#include <spdlog/spdlog.h>

#include <algorithm>
#include <chrono>
#include <cmath>

#include "base/guarded.hpp"
#include "analysis/zone_map.hpp"
#include "daemon/setup_record.hpp"
#include "store/database_export.hpp"
#include "base/text.hpp"
#include "base/user_error.hpp"

namespace manikind {

namespace {
std::int64_t steady_now_ns() {
    return std::chrono::duration_cast<std::chrono::nanoseconds>(std::chrono::steady_clock::now().time_since_epoch()).count();
}
}  // namespace

const char* stage_name(Stage s) {
    switch (s) {
        case Stage::idle: return "idle";
        case Stage::configuring: return "configuring";
        case Stage::chamber_settling: return "chamber_settling";
        case Stage::manikin_starting: return "manikin_starting";
        case Stage::acquiring: return "acquiring";
        case Stage::stopping: return "stopping";
        case Stage::computing: return "computing";
    }
    return "unknown";
}

namespace {
recorder::Durability durability_of(const config::Config& c) {
    return c.recorder_durability == "power" ? recorder::Durability::power : recorder::Durability::process;
}

recorder::Journal journal_of(const config::Config& c) {
    return c.recorder_journal == "rollback" ? recorder::Journal::rollback : recorder::Journal::wal;
}

recorder::RecorderOptions recorder_options_of(const config::Config& c) {
    recorder::RecorderOptions o;
    o.durability = durability_of(c);
    o.journal = journal_of(c);
    o.max_batch_delay = std::chrono::milliseconds(std::llround(c.recorder_commit_interval_s * 1000.0));
    o.lock_timeout = std::chrono::milliseconds(std::max<long long>(1, std::llround(c.recorder_lock_timeout_s * 1000.0)));
    o.crash_ring_dir = c.recorder_crash_ring_dir;
    return o;
}
}  // namespace

LabDaemon::LabDaemon(DaemonOptions options)
    : o_(std::move(options)),
      db_path_(o_.config.database.is_relative() && !o_.config.source_dir.empty() ? o_.config.source_dir / o_.config.database
                                                                                 : o_.config.database),
      db_lock_(InstanceLock::acquire(db_path_, "database")),
      // The recorder opens (creates, upgrades) the file; then the daemon's read-only connection.
      recorder_(std::make_unique<recorder::Recorder>(db_path_, recorder_options_of(o_.config))),
      db_(recorder::Database::open_read_only(db_path_)),
      row_mark_(db_.row_mark()) {
    last_tick_steady_ns_ = steady_now_ns();
    const auto [interrupted, campaigns_interrupted] = recorder_->call([&](recorder::Database& db) {
        // On the virtual clock the last thing recorded is when the run stopped; the wall clock
        // may lie months before it.
        std::int64_t ended_utc_ns = system_clock_.utc_ns();
        if (o_.virtual_clock && o_.config.mode == "simulated")
            if (const auto newest = db.newest_utc_ns()) ended_utc_ns = *newest;
        const int trials = db.mark_interrupted_trials(ended_utc_ns);
        return std::pair{trials, db.mark_interrupted_campaigns()};
    });
    if (interrupted > 0 || campaigns_interrupted > 0) {
        const std::string message = fmt::format("{} trial(s) and {} campaign(s) were running when the daemon stopped; "
                                                "marked interrupted (start the same campaign again to continue it)",
                                                interrupted, campaigns_interrupted);
        const std::int64_t utc_ns = system_clock_.utc_ns();
        write([=](recorder::Database& db) { db.add_event(std::nullopt, 0, utc_ns, "warn", "restart", message); });
    }
    skin_range_.resize(analysis::andi35_zone_map().size());
    auto sink = [this](const drivers::Sample& s) { on_sample(s); };
    if (o_.config.mode == "simulated") {
        // Time that does not repeat (issue 30): in real time the simulated lab stamps the wall
        // clock; on the virtual clock it starts at its fixed date (2026-06-01 09:00 UTC), or a
        // second after the newest stamp already in this database, so that nothing recorded by
        // an earlier run is ever met again and dropped as "already stored".
        std::int64_t start_utc_ns = o_.virtual_clock ? virtual_clock_.utc_ns() : system_clock_.utc_ns();
        if (const auto newest = db_.newest_utc_ns(); newest && *newest + 1'000'000'000 > start_utc_ns)
            start_utc_ns = *newest + 1'000'000'000;
        virtual_clock_.step_utc_ns(start_utc_ns - virtual_clock_.utc_ns());
        clock_ = &virtual_clock_;
        acq_ = std::make_unique<Acquisition>(o_.config, virtual_clock_, sink);
    } else {
        clock_ = &system_clock_;
        acq_ = std::make_unique<Acquisition>(o_.config, system_clock_, sink);
        o_.virtual_clock = false;
    }
    acq_->start();
    for (const auto& st : acq_->status()) {
        const std::string kind = st.name == "manikin" ? "can" : (st.name == "chamber" || st.name == "datalogger") ? "modbus" : "serial";
        device_ids_[st.name] = recorder_->call([&](recorder::Database& db) { return db.device_id(st.name, kind, st.transport); });
    }
    event("info", "daemon", fmt::format("started ({} lab, database {})", o_.config.mode, db_path_.string()));
    // Exports name the configuration their trials ran under by this fingerprint (provenance).
    if (!o_.config.source_sha256.empty())
        event("info", "config", fmt::format("sha256 {} {}", o_.config.source_sha256, o_.config.source_name));
    // Every trial of this run names its set-up: lab, chamber, manikin, calibration, configuration.
    const auto setup = setup_of(o_.config);
    const std::int64_t setup_utc_ns = clock_->utc_ns();
    setup_id_ = recorder_->call([&](recorder::Database& db) { return db.record_setup(setup, setup_utc_ns); });
}

LabDaemon::~LabDaemon() {
    stop();
    acq_.reset();
    recorder_.reset();
}

std::int64_t LabDaemon::recorded_channel(const std::string& device, const std::string& channel) {
    const std::string key = device + "/" + channel;
    if (const auto it = channel_ids_.find(key); it != channel_ids_.end()) return it->second;
    // Devices were registered with their kind and transport at start; device_id() would
    // overwrite those, so look the id up rather than calling it again.
    const auto dev = device_ids_.find(device);
    // Asked of the writer (the database's one writer); throws StorageBusy/Full/Fault at once while
    // it waits on storage (the caller keeps the reading: record_sample_locked).
    const std::int64_t id = recorder_->call([&](recorder::Database& db) {
        const std::int64_t device_id = dev != device_ids_.end() ? dev->second : db.device_id(device, "unknown", "");
        return db.channel_id(device_id, channel, drivers::unit_of_channel(channel));
    });
    channel_ids_[key] = id;
    return id;
}

std::int64_t LabDaemon::now_utc_ns() const { return clock_ ? clock_->utc_ns() : system_clock_.utc_ns(); }

void LabDaemon::event(const std::string& severity, const std::string& kind, const std::string& message) {
    log_event(severity, kind, message);
    if (severity == "warn" || severity == "error") {
        alarms_.raise(severity, kind, "", message, now_utc_ns());
        if (kind == "safety") notify_locked("safety", "error", "SAFETY STOP: heating stopped", message);
        else notify_locked(severity == "error" ? "alarm_error" : "alarm_warn", severity, fmt::format("alarm: {}", kind), message);
    }
}

void LabDaemon::set_notice_listener(NoticeListener listener) {
    std::lock_guard lk(lock_);
    notice_listener_ = std::move(listener);
}

void LabDaemon::notify_locked(const std::string& kind, const std::string& severity, const std::string& title, const std::string& body) {
    if (!notice_listener_) return;
    try {
        notice_listener_(kind, severity, title, body, now_utc_ns());
    } catch (const std::exception& e) {
        spdlog::warn("a notification could not be queued: {}", e.what());  // never the tick's problem
    }
}

void LabDaemon::log_event(const std::string& severity, const std::string& kind, const std::string& message) {
    const std::optional<std::int64_t> trial = trial_id_ ? std::optional<std::int64_t>(trial_id_) : std::nullopt;
    const std::int64_t mono_ns = clock_ ? clock_->mono_ns() : 0;
    const std::int64_t utc_ns = now_utc_ns();
    write([=](recorder::Database& db) { db.add_event(trial, mono_ns, utc_ns, severity, kind, message); });
    if (severity == "error") spdlog::error("{}: {}", kind, message);
    else if (severity == "warn") spdlog::warn("{}: {}", kind, message);
    else spdlog::debug("{}: {}", kind, message);
}

void LabDaemon::condition(const std::string& severity, const std::string& kind, const std::string& source,
                          const std::string& message) {
    // Stored and logged like any event; the alarm is one line while the condition lasts.
    const std::string sev = severity == "error" ? "error" : "warn";
    log_event(sev, kind, message);
    bool fresh = false;
    alarms_.raise(sev, kind, source, message, now_utc_ns(), &fresh);
    // Once per episode: a device dropping out every minute is one message, not sixty.
    if (fresh) notify_locked(sev == "error" ? "alarm_error" : "alarm_warn", sev, fmt::format("alarm: {} ({})", kind, source), message);
}

void LabDaemon::condition_cleared(const std::string& kind, const std::string& source, const std::string& message) {
    event("info", kind, message);
    alarms_.clear(kind, source, message, now_utc_ns());
}

void LabDaemon::external_event(const std::string& severity, const std::string& kind, const std::string& message) {
    std::lock_guard lk(lock_);
    event(severity, kind, message);
}

void LabDaemon::add_status_section(const std::string& name, std::function<nlohmann::json()> section) {
    std::lock_guard lk(lock_);
    status_sections_.emplace_back(name, std::move(section));
}

std::string LabDaemon::add_note(const std::string& campaign, std::optional<std::int64_t> trial_id, const std::string& kind,
                                const std::string& text, const std::string& author) {
    // Checked here, whoever asks (console, socket): the notebook holds text a person can read.
    if (!analysis::is_note_kind(kind)) return fmt::format("\"kind\": expected comment, operator, ensemble or garment, not '{}'", printable(kind, 40));
    // base/text.hpp's one rule: the author is a label (no control character: a NUL, CR or ESC
    // reached the HTML report), the text may hold newlines and tabs.
    if (const auto why = text_problem(text, analysis::kMaxNoteBytes); !why.empty())
        return fmt::format("\"text\": {}{}", why, why == "empty" ? " (a note needs words)" : "");
    if (const auto why = label_problem(author, 100); !why.empty()) return fmt::format("\"author\": {}", why);
    std::lock_guard lk(lock_);
    flush_all_locked();  // a campaign or trial created a moment ago is found
    const auto id = db_.find_campaign(campaign);
    if (!id) return fmt::format("\"campaign\": no campaign named '{}' in {}", printable(campaign, 100), db_path_.filename().string());
    if (trial_id) {
        const auto t = db_.trial(*trial_id);
        if (!t || t->campaign_id != *id) return fmt::format("\"trial\": no trial {} in campaign '{}'", *trial_id, campaign);
    }
    recorder::NoteRow note{0, *id, trial_id, now_utc_ns(), author, kind, text};
    bool stored = false;
    // Through the one writer, waited for: "stored" means in the database.
    const bool allowed = storage_allows_locked([&] { recorder_->call([&](recorder::Database& db) { db.add_note(note); }); stored = true; });
    if (!allowed || !stored) return "the database cannot be written now (see alarms); the note was not stored, try again";
    log_event("info", "note", fmt::format("note by {} on '{}'{}", printable(author, 100), campaign,
                                          trial_id ? fmt::format(" trial {}", *trial_id) : std::string()));
    return {};
}

std::variant<std::int64_t, std::string> LabDaemon::trial_by_label(const std::string& campaign, const std::string& label) {
    std::lock_guard lk(lock_);
    flush_all_locked();
    const auto id = db_.find_campaign(campaign);
    if (!id) return fmt::format("\"campaign\": no campaign named '{}' in {}", printable(campaign, 100), db_path_.filename().string());
    std::optional<std::int64_t> found;
    std::string known;
    for (const auto& [trial, name] : manikind::exported_trial_ids(db_, *id)) {
        if (name == label) found = std::max(found.value_or(0), trial);
        if (known.find(name) == std::string::npos) known += (known.empty() ? "" : ", ") + name;
    }
    if (found) return *found;
    return fmt::format("\"trial\": no trial '{}' in campaign '{}' (its trials so far: {})", printable(label, 40), printable(campaign, 100),
                       known.empty() ? "none" : known);
}

nlohmann::json LabDaemon::notes_json(const std::string& campaign) {
    std::lock_guard lk(lock_);
    flush_all_locked();
    const auto id = db_.find_campaign(campaign);
    if (!id) throw UserError(fmt::format("{}: no campaign named '{}'", db_path_.string(), printable(campaign, 100)));
    const auto trial_name = manikind::exported_trial_ids(db_, *id);  // the export's name of each trial (c03-r2)
    nlohmann::json out = nlohmann::json::array();
    for (const auto& n : db_.notes(*id)) {
        nlohmann::json e{{"id", n.id}, {"utc", analysis::iso_utc_ms(n.utc_ns)}, {"author", n.author}, {"kind", n.kind}, {"text", n.text}};
        e["trial_id"] = n.trial_id ? nlohmann::json(*n.trial_id) : nlohmann::json(nullptr);
        if (const auto it = n.trial_id ? trial_name.find(*n.trial_id) : trial_name.end(); it != trial_name.end()) e["trial"] = it->second;
        out.push_back(std::move(e));
    }
    return out;
}

nlohmann::json LabDaemon::alarms_json() {
    std::lock_guard lk(lock_);
    return alarms_.open_json();
}

nlohmann::json LabDaemon::alarm_history_json() {
    std::lock_guard lk(lock_);
    return alarms_.history_json();
}

// Each change of an alarm's state is an event in the database: the alarm's history survives the daemon.
std::string LabDaemon::acknowledge_alarm(std::int64_t id, const std::string& who) {
    std::lock_guard lk(lock_);
    const AlarmEntry* a = alarms_.find(id);
    const bool was_acked = a && a->acknowledged;
    const std::string message = a ? a->message : std::string();
    if (auto err = alarms_.acknowledge(id, who, now_utc_ns()); !err.empty()) return err;
    if (!was_acked) log_event("info", "alarm_ack", fmt::format("alarm {} acknowledged by {}: {}", id, who, message));
    return {};
}

std::string LabDaemon::shelve_alarm(std::int64_t id, double duration_s, const std::string& who) {
    std::lock_guard lk(lock_);
    if (auto err = alarms_.shelve(id, duration_s, who, now_utc_ns()); !err.empty()) return err;
    log_event("info", "alarm_shelve", fmt::format("alarm {} shelved by {} for {:.0f} min: {}", id, who, duration_s / 60.0,
                                                  alarms_.find(id)->message));
    return {};
}

std::string LabDaemon::unshelve_alarm(std::int64_t id, const std::string& who) {
    std::lock_guard lk(lock_);
    if (auto err = alarms_.unshelve(id, who); !err.empty()) return err;
    log_event("info", "alarm_shelve", fmt::format("alarm {} unshelved by {}", id, who));
    return {};
}

void LabDaemon::set_sample_listener(std::function<void()> listener) {
    std::lock_guard lk(lock_);
    sample_listener_ = std::move(listener);
}

void LabDaemon::on_sample(const drivers::Sample& s) {
    std::lock_guard lk(lock_);
    try {
        record_sample_locked(s);
    } catch (const recorder::StorageFull& e) {
        storage_stop_locked(e.what());
    } catch (const std::exception& e) {
        internal_error_locked("sample path", e.what());
    }
}

void LabDaemon::step_virtual(double dt_s) {
    std::lock_guard lk(lock_);
    step_rows_active_ = true;
    try {
        acq_->step(dt_s);
    } catch (...) {
        release_step_rows_locked();
        throw;
    }
    release_step_rows_locked();  // before the tick: it may end the trial and flush
    tick_locked();
    last_tick_steady_ns_ = steady_now_ns();
}

void LabDaemon::step_wall_clock_virtual(std::int64_t dt_ns) {
    std::lock_guard lk(lock_);
    if (!o_.virtual_clock) throw std::logic_error("step_wall_clock_virtual: the daemon runs on the system clock");
    virtual_clock_.step_utc_ns(dt_ns);
}

std::string LabDaemon::stage_line() {
    std::lock_guard lk(lock_);
    return current_ ? fmt::format("{} trial {}", stage_name(stage_), trial_id_) : std::string(stage_name(stage_));
}

void LabDaemon::run_virtual(std::function<void(const std::string&)> on_trial, double max_virtual_s) {
    const double dt = o_.config.simulation.step_s;
    std::size_t reported = 0;
    for (double t = 0; t < max_virtual_s; t += dt) {
        step_virtual(dt);
        std::lock_guard lk(lock_);
        while (reported < trial_summaries_.size()) {
            if (on_trial) on_trial(fmt::format("[{}/{}] {}", reported + 1, trials_total_, trial_summaries_[reported]));
            ++reported;
        }
        if (!plan_ && waiting_.empty()) break;
    }
    flush_recorder();
}

void LabDaemon::start_realtime() {
    acq_->start_realtime(o_.speed);
    stop_ = false;
    tick_thread_ = std::thread([this] {
        auto next = std::chrono::steady_clock::now();
        for (;;) {
            next += std::chrono::seconds(1);
            std::this_thread::sleep_until(next);
            std::lock_guard lk(lock_);
            if (stop_) break;
            tick_locked();
            last_tick_steady_ns_ = steady_now_ns();
        }
    });
}

double LabDaemon::seconds_since_tick() const {
    const auto now = steady_now_ns();
    return static_cast<double>(now - last_tick_steady_ns_.load()) * 1e-9;
}

void LabDaemon::stop() {
    if (interim_thread_.joinable()) interim_thread_.join();
    {
        std::lock_guard lk(lock_);
        stop_ = true;
    }
    if (tick_thread_.joinable()) tick_thread_.join();
    {
        // SIGTERM (or any stop) mid-campaign: the running trial and the campaign end
        // "interrupted" now, not at the next start; starting the same plan continues it.
        // Posted to the recorder like every write; if storage still waits at the end, the next
        // start marks what was running interrupted (mark_interrupted_trials).
        std::lock_guard lk(lock_);
        if (trial_id_) finish_trial("interrupted", "daemon stopped");
        if (plan_ && campaign_id_) {
            write([campaign = campaign_id_](recorder::Database& db) { db.set_campaign_state(campaign, "interrupted"); });
            event("warn", "campaign", fmt::format("'{}' interrupted: the daemon stopped (start it again to continue)", plan_->name));
            standby_locked(fmt::format("campaign '{}' interrupted", plan_->name));
            plan_.reset();
        }
    }
    if (acq_) {
        acq_->manikin().set_run(false);
        acq_->stop();
    }
    std::lock_guard lk(lock_);
    if (recorder_ && !flush_all_locked()) {
        const auto rs = recorder_->stats();
        spdlog::error("stopping with {} of the daemon's writes and {} readings not stored yet ({}): tried {} more times "
                      "as the recorder closes",
                      rs.jobs_waiting, rs.queue_depth + overflow_.size() + unnamed_.size(), rs.storage_error,
                      recorder::RecorderOptions{}.max_commit_attempts);
    }
}

nlohmann::json LabDaemon::status_json() {
    std::lock_guard lk(lock_);
    nlohmann::json j;
    j["mode"] = o_.config.mode;
    // "real" only for a real lab or a simulated one at 1x; a simulated lab sped up says so.
    j["clock"] = o_.virtual_clock ? "virtual" : (o_.config.mode == "simulated" && o_.speed != 1.0 ? "paced" : "real");
    j["speed"] = o_.virtual_clock ? nlohmann::json(nullptr) : nlohmann::json(o_.speed);
    j["database"] = db_path_.string();
    j["time_s"] = static_cast<double>(clock_->mono_ns()) * 1e-9;
    j["lab_utc_ms"] = clock_->utc_ns() / 1'000'000;  // the clock records are stamped with (a simulated lab's runs on its own)
    j["campaign"] = plan_ ? nlohmann::json(plan_->name) : nlohmann::json(nullptr);
    j["last_campaign"] = last_campaign_ ? nlohmann::json(*last_campaign_) : nlohmann::json(nullptr);
    j["queued_campaigns"] = nlohmann::json::array();
    for (const auto& p : waiting_) j["queued_campaigns"].push_back(p.name);
    j["stage"] = stage_name(stage_);
    j["paused"] = paused_;
    j["awaiting_operator"] = operator_prompt_ ? nlohmann::json(*operator_prompt_) : nlohmann::json(nullptr);
    j["trials_done"] = trials_done_;
    j["trials_total"] = trials_total_;
    if (current_) {
        j["trial"] = {{"case", current_->c.id}, {"replicate", current_->replicate}, {"id", trial_id_},
                      {"wet", current_->c.wet}, {"stage_elapsed_s", stage_elapsed_s()}};
        if (stage_ == Stage::chamber_settling) j["trial"]["settling"] = settling_json_locked(clock_->mono_ns());
        if (loop_) j["trial"]["model"] = loop_->status_json();  // a physiological trial: the model beside the zones
        // Each zone's skin setpoint, for the console's deviation view: the case's, or the model's last.
        nlohmann::json zone_sp = nlohmann::json::array();
        if (loop_) {
            for (const double v : loop_->zone_setpoints_c()) zone_sp.push_back(std::isfinite(v) ? nlohmann::json(v) : nlohmann::json(nullptr));
        } else if (comfort_) {
            // Comfort mode: each zone's setpoint from its own loss (the console's deviation view).
            j["trial"]["control"] = "comfort";
            j["trial"]["comfort_equation"] = {{"a_c", comfort_->equation().a_c}, {"b_c_m2_w", comfort_->equation().b_c_m2_w}};
            for (const double v : comfort_->zone_setpoints_c()) zone_sp.push_back(std::isfinite(v) ? nlohmann::json(v) : nlohmann::json(nullptr));
        } else if (current_->c.heat_flux_w_m2) {
            // Constant heat flux: the heating is the setpoint, the skin is measured (no skin setpoint).
            j["trial"]["control"] = "constant-heat-flux";
            j["trial"]["heat_flux_setpoint_w_m2"] = *current_->c.heat_flux_w_m2;
            if (!current_->c.heat_flux_by_region_w_m2.empty())
                j["trial"]["heat_flux_by_region_w_m2"] = current_->c.heat_flux_by_region_w_m2;
        } else if (!current_->c.model) {
            j["trial"]["skin_setpoint_c"] = current_->c.skin_setpoint_c;
        }
        j["trial"]["zone_setpoints_c"] = std::move(zone_sp);
        // A physiological trial has no steady state: the model's progress stands in its place (trial.model).
        if (stage_ == Stage::acquiring && !loop_) {
            const SteadyCheck c = check_steady_window_locked(paused_ ? paused_at_ns_ : clock_->mono_ns());
            const double limit_c = o_.config.steady_state.max_skin_fluctuation_c;
            const double elapsed_s = stage_elapsed_s();
            const double min_duration_s = plan_->trial_duration_s;
            // The rule (Methods): every zone's range over the window below the limit, and the
            // trial's duration reached.
            const bool steady = c.window_steady && elapsed_s >= min_duration_s;
            // Progress is the least-advanced of the rule's three conditions, so the bar cannot be
            // full while the rule says no.
            const double range_fraction =
                !std::isfinite(c.worst_zone_range_c) ? 0.0
                : c.worst_zone_range_c <= 0.0     ? 1.0
                                                  : std::min(1.0, limit_c / c.worst_zone_range_c);
            const double duration_fraction = min_duration_s > 0 ? std::min(1.0, elapsed_s / min_duration_s) : 1.0;
            double progress = std::min({c.window_filled_fraction, range_fraction, duration_fraction});
            if (!steady) progress = std::min(progress, 0.999);
            else progress = 1.0;
            auto& t = j["trial"];
            t["window_filled_fraction"] = c.window_filled_fraction;
            t["window_s"] = o_.config.steady_state.window_s;
            t["worst_zone_range_c"] = std::isfinite(c.worst_zone_range_c) ? nlohmann::json(c.worst_zone_range_c) : nlohmann::json(nullptr);
            const auto& zones = analysis::andi35_zone_map().zones;
            if (c.worst_zone >= 1 && c.worst_zone <= static_cast<int>(zones.size()))
                t["worst_zone"] = {{"zone", c.worst_zone}, {"name", zones[static_cast<std::size_t>(c.worst_zone - 1)].name}};
            else
                t["worst_zone"] = nullptr;
            t["limit_c"] = limit_c;
            t["elapsed_s"] = elapsed_s;
            t["min_duration_s"] = min_duration_s;
            t["window_steady"] = c.window_steady;
            // A clothing test also waits for the standards' steady heat loss (issue 64).
            const bool clothing = !current_->c.test.empty();
            const bool all_steady = steady && (!clothing || heat_loss_verdict_.steady);
            t["steady"] = all_steady;
            t["steady_progress"] = all_steady ? 1.0 : std::min(progress, 0.999);
            if (clothing)
                t["heat_loss"] = {{"observed", heat_loss_verdict_.observed},
                                  {"drift_fraction", heat_loss_verdict_.observed ? nlohmann::json(heat_loss_verdict_.drift_fraction) : nlohmann::json()},
                                  {"limit_fraction", analysis::HeatLossRule{}.max_drift_fraction},
                                  {"mean_skin_drift_c", heat_loss_verdict_.observed ? nlohmann::json(heat_loss_verdict_.mean_skin_drift_c) : nlohmann::json()},
                                  {"steady", heat_loss_verdict_.steady},
                                  {"failing", heat_loss_verdict_.failing}};
        }
    }
    nlohmann::json devices = nlohmann::json::array();
    for (const auto& s : acq_->status())
        devices.push_back({{"name", s.name}, {"transport", s.transport}, {"connected", s.connected}, {"stale", s.stale},
                           {"samples", s.samples}, {"frames", s.frames}, {"checksum_errors", s.checksum_errors},
                           {"malformed", s.malformed}, {"timeouts", s.timeouts}, {"exceptions", s.exceptions},
                           {"reconnects", s.reconnects}, {"comm_errors", s.comm_errors}, {"device_faults", s.device_faults},
                           {"last_error", s.last_error}});
    j["devices"] = devices;
    const auto rs = recorder_->stats();
    // Every reading not stored is counted here, whatever the cause (not only logged).
    j["recorder"] = {{"accepted", rs.accepted},
                     {"committed", rs.committed},
                     {"dropped", rs.dropped + dropped_samples_ + rs.duplicates + rs.lost},
                     {"dropped_queue_full", rs.dropped + dropped_samples_},
                     {"duplicates", rs.duplicates},
                     {"lost_after_retries", rs.lost},
                     {"queue_rows", rs.queue_depth},
                     {"recovered_from_crash_ring", rs.recovered},
                     {"crash_ring", rs.crash_ring},
                     {"journal", rs.journal},
                     {"locked", rs.locked},
                     {"locked_commits", rs.locked_commits}};
    j["storage"] = {{"full", storage_full_},
                    {"locked", storage_busy_},
                    {"busy_waits", storage_busy_waits_},
                    {"readings_waiting", overflow_.size() + unnamed_.size()},
                    {"error", storage_error_},
                    {"deferred_writes", rs.jobs_waiting},
                    {"io_error", rs.io_error},
                    {"io_error_commits", rs.io_error_commits},
                    {"writes_failed", rs.jobs_failed},
                    {"writes_lost", rs.jobs_lost},
                    {"full_disk_commits", rs.full_disk_commits}};
    // Exceptions that escaped a thread's body and were survived (base/guarded.hpp): 0 unless a bug.
    j["threads"] = {{"exceptions_survived", escaped_exceptions().load()}};
    j["safety_tripped"] = safety_tripped_;
    j["measured"] = measured_json_locked();
    for (const auto& [name, section] : status_sections_) j[name] = section();
    return j;
}

// The values an operator watches, from the live channels: each with unit, age and the channel(s)
// it came from. Mean skin temperature and heat flux are area-weighted over the zones whose last
// sample is good; their age is the oldest of those samples.
nlohmann::json LabDaemon::measured_json_locked() const {
    const std::int64_t now = clock_->mono_ns();
    auto null_if_nan = [](double v) { return std::isfinite(v) ? nlohmann::json(v) : nlohmann::json(nullptr); };
    auto one = [&](const std::string& key, const std::string& unit) {
        nlohmann::json m = {{"value", nullptr}, {"unit", unit}, {"age_s", nullptr}, {"quality", nullptr}, {"source", key}};
        if (const auto it = live_.find(key); it != live_.end()) {
            m["value"] = null_if_nan(it->second.value);
            m["age_s"] = static_cast<double>(now - it->second.mono_ns) * 1e-9;
            m["quality"] = drivers::to_string(it->second.quality);
        }
        return m;
    };
    auto zone_mean = [&](const std::string& suffix, const std::string& unit) {
        const auto& zones = analysis::andi35_zone_map().zones;
        double sum = 0, area = 0, oldest_s = 0;
        std::size_t used = 0;
        for (const auto& z : zones) {
            const auto it = live_.find(fmt::format("manikin/z{:02d}.{}", z.zone, suffix));
            if (it == live_.end() || it->second.quality != drivers::Quality::good || !std::isfinite(it->second.value)) continue;
            sum += it->second.value * z.area_m2;
            area += z.area_m2;
            oldest_s = std::max(oldest_s, static_cast<double>(now - it->second.mono_ns) * 1e-9);
            ++used;
        }
        return nlohmann::json{{"value", area > 0 ? nlohmann::json(sum / area) : nlohmann::json(nullptr)},
                              {"unit", unit},
                              {"age_s", used ? nlohmann::json(oldest_s) : nlohmann::json(nullptr)},
                              {"quality", used == zones.size() ? "good" : used ? "partial" : "none"},
                              {"zones_used", used},
                              {"source", "manikin/zNN." + suffix + " (area-weighted)"}};
    };
    nlohmann::json m;
    m["chamber_air_temp_c"] = one("datalogger/ee181_1.air_temp_c", "°C");
    m["chamber_air_temp_c"]["setpoint"] = null_if_nan(chamber_setpoint_temp_c_);
    m["chamber_air_rh_pct"] = one("datalogger/ee181_1.air_rh_pct", "%");
    m["chamber_air_rh_pct"]["setpoint"] = null_if_nan(chamber_setpoint_rh_pct_);
    m["air_speed_m_s"] = one("windsonic/air_speed_m_s", "m/s");
    m["mean_skin_temp_c"] = zone_mean("skin_temp_c", "°C");
    m["mean_heat_flux_w_m2"] = zone_mean("heat_flux_w_m2", "W/m²");
    return m;
}

nlohmann::json LabDaemon::live_json() {
    std::lock_guard lk(lock_);
    nlohmann::json j = nlohmann::json::object();
    for (const auto& [key, s] : live_)
        j[key] = {{"value", std::isfinite(s.value) ? nlohmann::json(s.value) : nlohmann::json(nullptr)},
                  {"unit", drivers::unit_of_channel(s.channel)}, {"quality", drivers::to_string(s.quality)}, {"age_s", static_cast<double>(clock_->mono_ns() - s.mono_ns) * 1e-9}};
    return j;
}

}  // namespace manikind
