#include "daemon/lab_daemon.hpp"

#include <fmt/format.h>
#include <spdlog/spdlog.h>

#include <algorithm>
#include <set>
#include <chrono>
#include <cctype>
#include <cmath>

#include "base/guarded.hpp"
#include "analysis/analyze.hpp"
#include "analysis/physio.hpp"
#include "analysis/recording.hpp"
#include "analysis/zone_map.hpp"
#include "store/database_export.hpp"
#include "analysis/reconcile/results_parity.hpp"
#include "daemon/setup_record.hpp"
#include "base/text.hpp"
#include "base/user_error.hpp"

namespace manikind {

namespace mc = protocol::manikin_can;

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

nlohmann::json LabDaemon::notes_json(const std::string& campaign) {
    std::lock_guard lk(lock_);
    flush_all_locked();
    const auto id = db_.find_campaign(campaign);
    if (!id) throw UserError(fmt::format("{}: no campaign named '{}'", db_path_.string(), printable(campaign, 100)));
    nlohmann::json out = nlohmann::json::array();
    for (const auto& n : db_.notes(*id)) {
        nlohmann::json e{{"id", n.id}, {"utc", analysis::iso_utc_ms(n.utc_ns)}, {"author", n.author}, {"kind", n.kind}, {"text", n.text}};
        e["trial_id"] = n.trial_id ? nlohmann::json(*n.trial_id) : nlohmann::json(nullptr);
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

namespace {
// The grid the campaign's results read the recordings on (CampaignReader's default: Text S3.2).
constexpr double kExportPeriod_s = 5.0;
// Readings held by the daemon while the recorder's queue is full (a lock held elsewhere): 48 bytes
// each, so at most ~100 MB, about 3 h of the simulated lab's ~200 channels at 1 Hz.
constexpr std::size_t kMaxOverflowRows = 2'000'000;
}  // namespace

void LabDaemon::record_sample_locked(const drivers::Sample& s) {
    slot_key_.assign(s.device).append(1, '/').append(s.channel);
    auto [found, fresh] = slots_.try_emplace(slot_key_);
    ChannelSlot& slot = found->second;
    if (fresh) {
        slot.live = &live_[slot_key_];
        slot.manikin = s.device == "manikin";
        slot.skin = slot.manikin && s.channel.ends_with(".skin_temp_c");
        slot.heater = slot.manikin && s.channel.ends_with(".heater_power_w_m2");
        if (slot.skin) slot.zone = std::atoi(s.channel.c_str() + 1);
        slot.enclosure_air = s.device == "datalogger" && s.channel == "ee181_1.air_temp_c";
        // The enclosure's means: every EE181 probe's air temperature and RH, every wall thermocouple.
        const auto member = [&](const char* prefix, const char* suffix) {
            return slot_key_.starts_with(prefix) && slot_key_.ends_with(suffix);
        };
        std::optional<Enclosure> quantity;
        if (member("datalogger/ee181_", ".air_temp_c")) quantity = Enclosure::air;
        else if (member("datalogger/ee181_", ".air_rh_pct")) quantity = Enclosure::rh;
        else if (member("datalogger/wall_tc_", ".wall_temp_c")) quantity = Enclosure::wall;
        if (quantity) {
            auto& members = enclosure_members_[static_cast<std::size_t>(*quantity)];
            const auto at = std::lower_bound(members.begin(), members.end(), slot_key_,
                                             [](const auto& m, const std::string& k) { return m.first < k; });
            members.insert(at, {slot_key_, slot.live});
        }
    }
    *slot.live = s;
    if (sample_listener_) sample_listener_();
    // Safety: enforced here, whatever a client asked for.
    if (slot.manikin && s.quality != drivers::Quality::comm_error && acq_ && acq_->manikin().running_command()) {
        const auto& lim = o_.config.safety;
        if (slot.skin && s.value > lim.max_skin_temp_c)
            safety_stop(fmt::format("{} = {:.2f} °C is above safety.max_skin_temp_c = {} °C", s.channel, s.value,
                                    lim.max_skin_temp_c));
        if (slot.heater && s.value > lim.max_heater_power_w_m2)
            safety_stop(fmt::format("{} = {:.1f} W/m² is above safety.max_heater_power_w_m2 = {} W/m²", s.channel, s.value,
                                    lim.max_heater_power_w_m2));
    }
    if (slot.skin && s.quality == drivers::Quality::good && stage_ == Stage::acquiring) {
        if (slot.zone >= 1 && slot.zone <= static_cast<int>(skin_range_.size()))
            skin_range_[static_cast<std::size_t>(slot.zone - 1)].push(s.mono_ns, s.value);
    }
    if (slot.enclosure_air && s.quality == drivers::Quality::good) enclosure_range_.push(s.mono_ns, s.value);
    if (trial_id_ == 0) {
        // Outside trials: the idle log, one reading per channel per idle_log_period_s.
        const double period_s = o_.config.idle_log_period_s;
        if (period_s <= 0) return;
        if (slot.idle_logged_ns) {
            if (static_cast<double>(s.mono_ns - *slot.idle_logged_ns) < period_s * 1e9) return;
        }
        slot.idle_logged_ns = s.mono_ns;
    }
    std::int64_t channel_id = slot.channel_id;
    if (channel_id == 0) {
        // The key anew: a safety stop above may have recorded readings through slot_key_.
        const std::string key = s.device + "/" + s.channel;
        if (const auto known = channel_ids_.find(key); known != channel_ids_.end()) {
            channel_id = known->second;  // added by retry_unnamed_locked
        } else if (!unnamed_.empty() ||
                   !storage_allows_locked([&] { channel_id = recorded_channel(s.device, s.channel); })) {
            // A channel not yet in the database while storage waits (locked, full, failing): the
            // reading waits with its name and is recorded once the channel can be added
            // (retry_unnamed_locked), after those already waiting.
            hold_unnamed_locked(s);
            return;
        }
        slot.channel_id = channel_id;  // from now on: no lookup, no call to the writer
    }
    recorder::SampleRow row{trial_id_, channel_id, s.mono_ns, s.utc_ns, s.value, static_cast<std::uint8_t>(s.quality)};
    offer_row_locked(row);
}

void LabDaemon::hold_unnamed_locked(const drivers::Sample& s) {
    if (unnamed_.size() < kMaxOverflowRows) unnamed_.emplace_back(s, trial_id_);
    else ++dropped_samples_;
}

// Each tick: the held readings whose channel can now be added go on, in the order they came.
void LabDaemon::retry_unnamed_locked() {
    while (!unnamed_.empty()) {
        // Not a structured binding: clang 14 refuses to capture one in the lambda below.
        const drivers::Sample& s = unnamed_.front().first;
        const std::int64_t trial = unnamed_.front().second;
        std::int64_t channel_id = 0;
        if (!storage_allows_locked([&] { channel_id = recorded_channel(s.device, s.channel); })) return;
        offer_row_locked({trial, channel_id, s.mono_ns, s.utc_ns, s.value, static_cast<std::uint8_t>(s.quality)});
        unnamed_.pop_front();
    }
}

void LabDaemon::offer_row_locked(const recorder::SampleRow& row) {
    if (row.trial_id != 0 && !recorded_bins_.empty()) {
        if (current_bins_ && row.trial_id == trial_id_) current_bins_->add(row);
        else if (const auto it = recorded_bins_.find(row.trial_id); it != recorded_bins_.end()) it->second->add(row);  // sealed: unusable
    }
    if (step_rows_active_) {
        step_rows_.push_back(row);  // handed over when the step's reads are done (step_virtual)
        return;
    }
    offer_now_locked(row);
}

// A virtual-clock step's readings, handed to the recorder under one lock instead of one each
// (the lock was ~4 % of the 1-s daemon's CPU, issue 36). They wait only while this thread reads
// the step's frames and lines, microseconds of wall time, in memory as a reading still in its
// socket would; what the recorder's queue has no room for takes the one-by-one path, in order.
void LabDaemon::release_step_rows_locked() {
    step_rows_active_ = false;
    const std::size_t taken = overflow_.empty() ? recorder_->offer_many(step_rows_) : 0;
    for (std::size_t i = taken; i < step_rows_.size(); ++i) offer_now_locked(step_rows_[i]);
    step_rows_.clear();
}

void LabDaemon::offer_now_locked(const recorder::SampleRow& row) {
    // In order: while readings wait in the overflow, a new one waits behind them (the recorder
    // takes a reading older than one it stored for a re-sent duplicate).
    const bool waiting = !overflow_.empty();
    if (!waiting && recorder_->offer(row)) return;
    if (storage_full_) {  // heating is off; readings while the disk is full are counted, not kept
        if (!recorder_->push(row)) ++dropped_samples_;  // the recorder counts it dropped too
        return;
    }
    if (!waiting && o_.virtual_clock && !storage_busy_) {
        // Virtual time waits for the disk; nothing is dropped (unless the disk is full).
        if (recorder_->flush() && recorder_->offer(row)) return;
        if (const auto rs = recorder_->stats(); rs.storage_full) {
            storage_stop_locked(rs.storage_error);
            return;
        }
        watch_storage_locked();
    }
    // The recorder's queue is full (a lock held elsewhere, a slow disk): the reading waits here,
    // in order, and is handed over at the next ticks. Only past this bound is one dropped.
    if (overflow_.size() < kMaxOverflowRows) overflow_.push_back(row);
    else if (!recorder_->push(row)) ++dropped_samples_;
}

void LabDaemon::drain_overflow_locked() {
    while (!overflow_.empty() && recorder_->offer(overflow_.front())) overflow_.pop_front();
}

bool LabDaemon::flush_all_locked() {
    // The writer tries what waits at its head first: its state then says whether new channels can be added.
    if (!unnamed_.empty() && recorder_->flush()) retry_unnamed_locked();
    while (!overflow_.empty()) {
        drain_overflow_locked();
        if (!overflow_.empty() && !recorder_->flush()) break;  // locked or full: the rest waits for a later tick
    }
    return recorder_->flush() && overflow_.empty() && unnamed_.empty();
}

// The enclosure's air (°C) or RH (%), the mean of the EE181 probes' good live readings, or its
// wall temperature, the thermocouples' (the channels under `prefix` ending in `quantity_suffix`);
// NaN without one.
double LabDaemon::enclosure_mean(Enclosure quantity) const {
    double sum = 0;
    int n = 0;
    for (const auto& [key, s] : enclosure_members_[static_cast<std::size_t>(quantity)])
        if (s->quality == drivers::Quality::good) sum += s->value, ++n;
    return n ? sum / n : std::nan("");
}

nlohmann::json LabDaemon::settling_json_locked(std::int64_t now) const {
    const EnclosureTarget& target = target_;
    const double air = enclosure_air_c(), rh = enclosure_rh_pct();
    const double air_off = air - target.air_c, rh_off = rh - target.rh_pct;
    const double window_s = plan_->settle_window_s;
    const double on_target_s = on_target_since_ns_ ? static_cast<double>(now - *on_target_since_ns_) * 1e-9 : 0.0;
    // ETA: on target, what the window still needs; off target and closing in, the time to the
    // tolerance at the last minutes' rate, plus the window; else unknown (null).
    nlohmann::json eta = nullptr;
    if (on_target_since_ns_) {
        eta = std::max(0.0, window_s - on_target_s);
    } else if (std::isfinite(air_off) && settle_off_history_.size() >= 2) {
        const auto& [t0, off0] = settle_off_history_.front();
        const auto& [t1, off1] = settle_off_history_.back();
        const double rate_c_per_s = (off0 - off1) / (static_cast<double>(t1 - t0) * 1e-9);
        const double left_c = std::abs(air_off) - plan_->settle_tolerance_c;
        if (rate_c_per_s > 1e-5 && left_c > 0) eta = left_c / rate_c_per_s + window_s;
        else if (left_c <= 0) eta = window_s;  // the temperature is there; RH is what is awaited
    }
    auto number_or_null = [](double v) { return std::isfinite(v) ? nlohmann::json(v) : nlohmann::json(nullptr); };
    return {{"criterion", fmt::format("enclosure air within {} °C of {} °C and RH within {} % of {} %, varying less than "
                                      "{} °C, for {:.0f} min",
                                      plan_->settle_tolerance_c, target.air_c, plan_->settle_tolerance_rh_pct,
                                      target.rh_pct, plan_->settle_band_c, window_s / 60)},
            {"target_air_c", target.air_c},
            {"air_c", number_or_null(air)},
            {"air_off_c", number_or_null(air_off)},
            {"tolerance_c", plan_->settle_tolerance_c},
            {"target_rh_pct", target.rh_pct},
            {"rh_pct", number_or_null(rh)},
            {"rh_off_pct", number_or_null(rh_off)},
            {"tolerance_rh_pct", plan_->settle_tolerance_rh_pct},
            {"range_c", enclosure_range_.empty() ? nlohmann::json(nullptr) : nlohmann::json(enclosure_range_.range())},
            {"band_c", plan_->settle_band_c},
            {"on_target_s", on_target_s},
            {"window_s", window_s},
            {"eta_s", eta},
            {"timeout_s", plan_->settle_timeout_s},
            {"timed_out", settle_timeout_alarmed_}};
}


LabDaemon::SteadyCheck LabDaemon::check_steady_window_locked(std::int64_t now) {
    const double window_s = o_.config.steady_state.window_s;
    SteadyCheck c;
    const double acquiring_s = static_cast<double>(now - acquiring_since_ns_) * 1e-9;
    c.window_filled_fraction = window_s > 0 ? std::clamp(acquiring_s / window_s, 0.0, 1.0) : 1.0;
    bool observed = acquiring_s >= window_s;
    double worst = -1.0;
    for (std::size_t i = 0; i < skin_range_.size(); ++i) {
        auto& r = skin_range_[i];
        r.evict_before(now - static_cast<std::int64_t>(window_s * 1e9));
        if (r.empty()) {
            observed = false;
        } else if (r.range() > worst) {
            worst = r.range();
            c.worst_zone = static_cast<int>(i + 1);
        }
    }
    if (worst >= 0.0) c.worst_zone_range_c = worst;
    // Methods: "< 0.05 °C", strictly, as the analysis applies it.
    c.window_steady = observed && worst >= 0.0 && worst < o_.config.steady_state.max_skin_fluctuation_c;
    return c;
}

double LabDaemon::stage_elapsed_s() const {
    const std::int64_t now = paused_ ? paused_at_ns_ : clock_->mono_ns();
    return static_cast<double>(now - stage_start_ns_) * 1e-9;
}

void LabDaemon::enter(Stage s, const std::string& why) {
    stage_ = s;
    device_retry_logged_ = false;
    stage_start_ns_ = clock_->mono_ns();
    // The grid's start is the "acquiring" event's time: on the virtual clock the same reading of
    // it (elsewhere the reader finds the two differ and reads the trial back).
    if (s == Stage::acquiring && current_bins_) current_bins_->start(stage_start_ns_);
    event("info", "stage", stage_name(s));
    if (!why.empty()) event("info", "stage_reason", why);
    if (trial_id_) {
        const std::int64_t trial = trial_id_, utc_ns = clock_->utc_ns();
        const std::string state = stage_name(s);
        write([=](recorder::Database& db) { db.set_trial_state(trial, state, why, utc_ns); });
    }
}

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
    waiting_.clear();  // an operator's abort stops what was queued too
    finish_campaign("aborted");
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
    stage_start_ns_ += clock_->mono_ns() - paused_at_ns_;  // the stage's clock stood still
    paused_ = false;
    event("info", "campaign", "resumed");
    return {};
}

std::string LabDaemon::set_chamber(double temp_c, double rh_pct) {
    std::lock_guard lk(lock_);
    const auto& l = o_.config.safety;
    if (temp_c < l.min_chamber_temp_c || temp_c > l.max_chamber_temp_c)
        return fmt::format("chamber_temp_c {} is outside the safety limits {}..{} °C (safety.min/max_chamber_temp_c)", temp_c,
                           l.min_chamber_temp_c, l.max_chamber_temp_c);
    if (rh_pct < l.min_chamber_rh_pct || rh_pct > l.max_chamber_rh_pct)
        return fmt::format("chamber_rh_pct {} is outside the safety limits {}..{} % (safety.min/max_chamber_rh_pct)", rh_pct,
                           l.min_chamber_rh_pct, l.max_chamber_rh_pct);
    if (auto why = acq_->chamber().write("air_temp_remote_setpoint_c", temp_c); !why.empty()) return why;
    if (auto why = acq_->chamber().write("air_rh_remote_setpoint_pct", rh_pct); !why.empty()) return why;
    chamber_setpoint_temp_c_ = temp_c;
    chamber_setpoint_rh_pct_ = rh_pct;
    event("info", "setpoint", fmt::format("chamber {} °C, {} %", temp_c, rh_pct));
    return {};
}

void LabDaemon::safety_stop(const std::string& why) {
    if (safety_tripped_) return;
    safety_tripped_ = true;
    acq_->manikin().set_run(false);
    event("error", "safety", "heating stopped: " + why);
    if (trial_id_) {
        const std::int64_t trial = trial_id_;
        write([=](recorder::Database& db) { db.add_trial_flag(trial, flag_safety_stop); });
        finish_trial("failed", "safety stop: " + why);
    }
    waiting_.clear();
    if (plan_) finish_campaign("aborted");
}

void LabDaemon::write(recorder::Recorder::Job job) {
    // Made now, as before the daemon goes on (a kill -9 right after loses nothing it said it did);
    // while storage waits (locked, full, failing) the recorder keeps it in line, in order, and
    // makes it when it can. Only past its bound (100,000 writes waiting) is one refused, and
    // counted (status storage.writes_lost).
    if (storage_allows_locked([&] { recorder_->call(job); })) return;
    if (!recorder_->post(std::move(job)))
        spdlog::error("a write to the database was refused: {} already wait", recorder::RecorderOptions{}.max_jobs);
}

void LabDaemon::storage_stop_locked(const std::string& why) {
    if (storage_full_) return;
    storage_full_ = true;
    storage_error_ = why;
    const auto rs = recorder_->stats();
    dropped_when_full_ = rs.dropped;
    jobs_lost_when_full_ = rs.jobs_lost;
    if (acq_) acq_->manikin().set_run(false);  // no heating that cannot be recorded
    const std::string running = plan_ ? fmt::format(" '{}' interrupted (start it again to continue);", plan_->name) : "";
    condition("error", "disk_full", "database",
              fmt::format("disk full: heating stopped;{} recording resumes by itself when space is freed ({})", running, why));
    if (trial_id_) {
        const std::int64_t trial = trial_id_, utc_ns = clock_->utc_ns();
        const std::string reason = "disk full";
        write([=](recorder::Database& db) { db.set_trial_state(trial, "interrupted", reason, utc_ns); });
        trial_summaries_.push_back(fmt::format("case {} replicate {}: interrupted (disk full)", current_->c.id,
                                               current_->replicate));
        if (current_bins_) current_bins_->seal();
        current_bins_ = nullptr;
        trial_id_ = 0;
        current_.reset();
        ++trials_done_;
    }
    if (plan_) {
        const std::int64_t campaign = campaign_id_;
        write([=](recorder::Database& db) { db.set_campaign_state(campaign, "interrupted"); });
        plan_.reset();
    }
    queue_.clear();
    waiting_.clear();
    paused_ = false;
    stage_ = Stage::idle;
}

// Another program (or a reader) held the database's write lock past the busy timeout: the write
// waits in the recorder's line, in order with everything after it, and is made when the lock is
// gone; acquisition and the trial go on. Said once per episode, counted in status.
void LabDaemon::storage_busy_locked(const std::string& why) {
    ++storage_busy_waits_;
    if (storage_busy_) return;
    storage_busy_ = true;
    condition("error", "database_locked", "database",
              fmt::format("the database is locked ({}); the daemon's writes wait in order and are made when it is free: "
                          "nothing is lost", why));
}

// Runs a call to the writer; false (the alarm for that kind raised) when storage refused it.
bool LabDaemon::storage_allows_locked(const std::function<void()>& call) {
    try {
        call();
        return true;
    } catch (const recorder::StorageBusy& e) {
        storage_busy_locked(e.what());
    } catch (const recorder::StorageFull& e) {
        storage_stop_locked(e.what());
    } catch (const recorder::StorageFault& e) {
        storage_fault_locked(e.what());
    }
    return false;
}

void LabDaemon::storage_fault_locked(const std::string& why) {
    if (storage_fault_) return;
    storage_fault_ = true;
    condition("error", "storage_error", "database",
              fmt::format("the file system fails the database's writes ({}); readings and writes wait in memory, tried "
                          "again each second: nothing is lost", why));
}

// Each tick: the recorder's state (it retries each second) raises and clears the alarms for a
// lock held elsewhere and for a failing file system; a full disk has its own path (storage_stop_locked).
void LabDaemon::watch_storage_locked() {
    const auto rs = recorder_->stats();
    if (rs.locked) storage_busy_locked(rs.storage_error);
    if (rs.io_error) storage_fault_locked(rs.storage_error);
    const bool clear = !rs.locked && !rs.io_error && overflow_.empty() && unnamed_.empty() && rs.jobs_waiting == 0;
    if (storage_busy_ && clear) {
        storage_busy_ = false;
        condition_cleared("database_locked", "database",
                          fmt::format("the database is free again: every waiting write made ({} waits)", storage_busy_waits_));
    }
    if (storage_fault_ && clear) {
        storage_fault_ = false;
        condition_cleared("storage_error", "database", "the file system writes again: every waiting write made");
    }
}

// Each tick while the disk is full: once the recorder commits again, say so.
void LabDaemon::retry_storage_locked() {
    const auto rs = recorder_->stats();
    if (rs.storage_full || rs.jobs_waiting > 0) return;  // the recorder retries each second (and at each flush)
    storage_full_ = false;
    condition_cleared("disk_full", "database",
          fmt::format("space is back: recording resumed; {} readings were dropped while the disk was full{}",
                      rs.dropped - dropped_when_full_,
                      rs.jobs_lost > jobs_lost_when_full_ ? fmt::format(", {} events not kept", rs.jobs_lost - jobs_lost_when_full_)
                                                          : ""));
    storage_error_.clear();
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

void LabDaemon::finish_trial(const std::string& state, const std::string& reason) {
    flush_all_locked();
    if (current_bins_) current_bins_->seal();
    current_bins_ = nullptr;
    {
        const std::int64_t trial = trial_id_, utc_ns = clock_->utc_ns();
        const bool dropped = dropped_samples_ != 0;
        write([=](recorder::Database& db) {
            db.set_trial_state(trial, state, reason, utc_ns);
            if (dropped) db.add_trial_flag(trial, flag_dropped_samples);
            db.refresh_trial_table();  // a column for every channel this trial recorded
        });
    }
    trial_summaries_.push_back(fmt::format("case {} replicate {}: {}{}", current_->c.id, current_->replicate, state,
                                           reason.empty() ? "" : " (" + reason + ")"));
    notify_locked("trial_end", state == "done" ? "info" : "warn",
                  fmt::format("trial {} (case {} replicate {}) {}", trial_id_, current_->c.id, current_->replicate, state),
                  fmt::format("'{}': {}{}; {} of {} trials ended", plan_ ? plan_->name : std::string("?"), state,
                              reason.empty() ? "" : " (" + reason + ")", trials_done_ + 1, trials_total_));
    trial_id_ = 0;
    current_.reset();
    loop_.reset();
    ++trials_done_;
    stage_ = Stage::idle;
    if (state == "done" && interim_results_.value_or(!o_.virtual_clock) && !queue_.empty()) start_interim_results();
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
    for (const auto& t : db_.trials(*id)) {
        ++by_state[t.state];
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
            // Every case x replicate tried has a done trial (an interrupted one run again counts once).
            {"ok", !active && state == "done" && done.size() == tried.size() && planned > 0}};
}

namespace {
// How long a device's refusal of a trial's setpoint is retried before the trial fails.
constexpr double kDeviceRetryTimeoutS = 300.0;
}  // namespace

// A device refused this stage's setpoint: warn once and let the next tick try again; after
// kDeviceRetryTimeoutS in the stage the trial fails. `detail` is ": <device's reason>" or empty.
void LabDaemon::setpoint_refused(const std::string& what, const std::string& detail) {
    const double minutes = kDeviceRetryTimeoutS / 60;
    if (stage_elapsed_s() > kDeviceRetryTimeoutS) {
        finish_trial("failed", fmt::format("{} for {:.0f} min{}", what, minutes, detail));
    } else if (!device_retry_logged_) {
        device_retry_logged_ = true;
        event("warn", "setpoint", fmt::format("{}, retrying for up to {:.0f} min{}", what, minutes, detail));
    }
}

void LabDaemon::tick_locked() {
    // A shelf ends by itself: the alarm is shown again, and the log says so.
    for (const std::int64_t id : alarms_.expire_shelves(now_utc_ns())) log_event("info", "alarm_shelve", fmt::format("alarm {}: its shelf ended", id));
    try {
        if (!storage_full_) {
            if (const auto rs = recorder_->stats(); rs.storage_full) storage_stop_locked(rs.storage_error);
        }
        if (storage_full_) retry_storage_locked();
        else {
            retry_unnamed_locked();
            drain_overflow_locked();
            watch_storage_locked();
        }
        advance_locked();
    } catch (const recorder::StorageFull& e) {
        storage_stop_locked(e.what());
    } catch (const recorder::StorageBusy& e) {
        storage_busy_locked(e.what());  // this step is tried again at the next tick
    } catch (const recorder::StorageFault&) {
        watch_storage_locked();  // likewise
    } catch (const std::exception& e) {
        // Nothing leaves the thread (std::terminate would end recording and control): a bug or
        // bad data stops heating and ends the campaign, with an alarm saying what happened.
        internal_error_locked("trial state machine", e.what());
    } catch (...) {
        internal_error_locked("trial state machine", "an exception that is not a std::exception");
    }
}

void LabDaemon::internal_error_locked(const std::string& where, const std::string& what) {
    spdlog::critical("internal error in the {}: {}", where, what);
    try {
        safety_stop(fmt::format("internal error in the {}: {}", where, what));
    } catch (const std::exception& e) {
        if (acq_) acq_->manikin().set_run(false);
        spdlog::critical("stopping safely after that failed too: {}", e.what());
    }
}

// The trial state machine: one transition check per call (every tick of the clock).
void LabDaemon::advance_locked() {
    const std::int64_t now = clock_->mono_ns();
    // Gaps: a device that goes stale or disconnects is recorded, and flags the running trial.
    for (const auto& st : acq_->status()) {
        const bool down = st.stale || !st.connected;
        const auto it = gap_since_ns_.find(st.name);
        if (down && it == gap_since_ns_.end()) {
            gap_since_ns_[st.name] = now;
            condition("warn", "gap", st.name,
                      fmt::format("{} lost ({}){}", st.name, st.connected ? "stale" : "disconnected",
                                  st.last_error.empty() ? "" : ": " + st.last_error));
            if (trial_id_) write([=, trial = trial_id_](recorder::Database& db) { db.add_trial_flag(trial, flag_device_gap); });
        } else if (!down && it != gap_since_ns_.end()) {
            condition_cleared("gap", st.name,
                              fmt::format("{} back after {:.0f} s", st.name, static_cast<double>(now - it->second) * 1e-9));
            gap_since_ns_.erase(it);
        }
    }
    // Watchdog: heating with a silent manikin or chamber is not allowed.
    if (acq_->manikin().running_command()) {
        const double limit_s = o_.config.safety.watchdog_timeout_s;
        for (const char* dev : {"manikin", "chamber"}) {
            const auto it = gap_since_ns_.find(dev);
            if (it != gap_since_ns_.end() && static_cast<double>(now - it->second) * 1e-9 > limit_s)
                safety_stop(fmt::format("watchdog: {} silent for more than safety.watchdog_timeout_s = {} s", dev, limit_s));
        }
    }
    // A campaign queued behind the one that ended: begun once its writes can be made (begin_campaign
    // throws, changing nothing, while storage waits; this is tried again at the next tick).
    if (!plan_ && !waiting_.empty() && !storage_full_ && flush_all_locked()) {
        begin_campaign(waiting_.front());
        waiting_.pop_front();
    }
    if (!plan_ || paused_) return;
    const double elapsed = stage_elapsed_s();
    switch (stage_) {
        case Stage::idle: {
            if (queue_.empty()) {
                finish_campaign("done");
                return;
            }
            // Created before the queue lets go of it: a locked database leaves it queued for the next tick.
            const auto& next = queue_.front();
            const std::int64_t campaign = campaign_id_, setup = setup_id_;
            const std::int64_t trial = recorder_->call([&](recorder::Database& db) {
                std::int64_t id = 0;
                db.atomically([&] {
                    id = db.create_trial(campaign, next.case_id, next.replicate);
                    db.set_trial_setup(id, setup);
                });
                return id;
            });
            current_ = queue_.front();
            queue_.pop_front();
            trial_id_ = trial;
            dropped_samples_ = 0;
            begin_trial_bins_locked(trial);
            enter(Stage::configuring, fmt::format("case {} replicate {}", current_->c.id, current_->replicate));
            [[fallthrough]];
        }
        case Stage::configuring: {
            // A chamber that answers with an exception or not at all for a while (a controller
            // rebooting) is retried each tick, not failed at once: otherwise a 4-min glitch fails
            // every queued trial in as many ticks. The plan was checked against [safety] already.
            if (const auto why = set_chamber(current_->c.chamber_temp_c, current_->c.chamber_rh_pct); !why.empty()) {
                setpoint_refused("chamber setpoint refused", ": " + why);
                return;
            }
            enclosure_range_.clear();
            on_target_since_ns_.reset();
            settle_timeout_alarmed_ = false;
            settle_off_history_.clear();
            target_ = enclosure_target(current_->c);  // once a trial: settling and excursions read it each tick
            // A clothing test: the operator dresses the manikin for this trial (re-dressed for
            // every replicate). On the simulated lab the world puts the wardrobe's ensemble on.
            if (auto* lab = acq_ ? acq_->lab() : nullptr; lab && current_->c.ensemble.empty()) {
                lab->dress("");  // not a clothing test: bare
            } else if (!current_->c.ensemble.empty()) {
                if (lab) {
                    if (!lab->dress(current_->c.ensemble))
                        event("warn", "clothing",
                              fmt::format("the simulated lab's wardrobe has no ensemble '{}': the manikin runs bare",
                                          current_->c.ensemble));
                } else {
                    event("info", "clothing", fmt::format("dress the manikin: {} ({} test)", current_->c.ensemble, current_->c.test));
                }
            }
            enter(Stage::chamber_settling,
                  fmt::format("waiting for the enclosure at {} ± {} °C, {} ± {} % RH, stable for {:.0f} min",
                              target_.air_c, plan_->settle_tolerance_c, target_.rh_pct,
                              plan_->settle_tolerance_rh_pct, plan_->settle_window_s / 60));
            return;
        }
        case Stage::chamber_settling: {
            // Settled (issue 31): on target (air and RH within tolerance of the case's enclosure
            // target) continuously for the window, and varying less than the band over it. Stable
            // alone is not enough: an enclosure still creeping towards its setpoint is stable
            // within 0.3 °C over 10 min while 2 °C short.
            const auto window_ns = static_cast<std::int64_t>(plan_->settle_window_s * 1e9);
            enclosure_range_.evict_before(now - window_ns - 1'000'000'000);  // a reading's period of slack
            const auto& c = current_->c;
            const EnclosureTarget& target = target_;
            const double air = enclosure_air_c(), rh = enclosure_rh_pct();
            const bool on_target = std::isfinite(air) && std::abs(air - target.air_c) <= plan_->settle_tolerance_c &&
                                   (!std::isfinite(rh) || std::abs(rh - target.rh_pct) <= plan_->settle_tolerance_rh_pct);
            if (!on_target) on_target_since_ns_.reset();
            else if (!on_target_since_ns_) on_target_since_ns_ = now;
            if (std::isfinite(air)) {
                settle_off_history_.emplace_back(now, std::abs(air - target.air_c));
                while (settle_off_history_.size() > 2 && now - settle_off_history_.front().first > 300'000'000'000LL)
                    settle_off_history_.pop_front();
            }
            const bool stable = !enclosure_range_.empty() && enclosure_range_.range() < plan_->settle_band_c;
            if (on_target && stable && now - *on_target_since_ns_ >= window_ns) {
                enter(Stage::manikin_starting,
                      fmt::format("enclosure on target: {:.2f} °C (target {} ± {}), {:.1f} % RH (target {} ± {}), varying "
                                  "{:.2f} °C over {:.0f} min",
                                  air, target.air_c, plan_->settle_tolerance_c, rh, target.rh_pct,
                                  plan_->settle_tolerance_rh_pct, enclosure_range_.range(), plan_->settle_window_s / 60));
            } else if (elapsed > plan_->settle_timeout_s && !settle_timeout_alarmed_) {
                // Held, not failed: the manikin never starts off target; the operator decides.
                settle_timeout_alarmed_ = true;
                event("error", "settle_timeout",
                      fmt::format("case {} replicate {}: the enclosure is not on target after {:.0f} min ({:.2f} °C for {} ± "
                                  "{}, {:.1f} % RH for {} ± {}); holding: the manikin starts only on target (check the "
                                  "chamber, or abort)",
                                  c.id, current_->replicate, plan_->settle_timeout_s / 60, air, target.air_c,
                                  plan_->settle_tolerance_c, rh, target.rh_pct, plan_->settle_tolerance_rh_pct));
            }
            return;
        }
        case Stage::manikin_starting: {
            if (current_->c.model) {
                // Physiological control: the loop preconditions the zones, then the model decides.
                try {
                    loop_ = std::make_unique<PhysiologicalLoop>(*current_->c.model, o_.config.physiological,
                                                                analysis::andi35_zone_map());
                } catch (const std::exception& e) {
                    event("error", "physiological", fmt::format("the trial cannot run under the model: {}", e.what()));
                    finish_trial("failed", e.what());
                    return;
                }
                if (!acq_->manikin().set_run(true)) {
                    loop_.reset();
                    setpoint_refused("the manikin bus refused the run command", "");
                    return;
                }
                steady_since_ns_.reset();
                acquiring_since_ns_ = now;
                enter(Stage::acquiring, fmt::format("physiological control: {}, {} met, {:.0f} min", current_->c.model->name,
                                                    current_->c.model->metabolic_met, current_->c.model->duration_s / 60));
                physiological_tick_locked(now);
                return;
            }
            mc::Setpoint sp;
            sp.zone = 0;
            sp.mode = mc::ControlMode::constant_skin_temp;
            sp.value = current_->c.skin_setpoint_c;
            sp.sweating = current_->c.wet;
            sp.sweat_rate_g_m2_h = current_->c.sweat_rate_g_m2_h;
            if (!acq_->manikin().send(sp) || !acq_->manikin().set_run(true)) {
                setpoint_refused("the manikin bus refused the setpoint", "");  // a bus-off recovers in seconds
                return;
            }
            for (auto& r : skin_range_) r.clear();
            steady_since_ns_.reset();
            acquiring_since_ns_ = now;
            off_target_since_ns_.reset();
            in_excursion_ = false;
            enter(Stage::acquiring, fmt::format("skin {} °C, {}", sp.value, sp.sweating ? "wet" : "dry"));
            return;
        }
        case Stage::acquiring: {
            if (loop_) {  // no steady state and no excursions: the chamber follows the protocol
                physiological_tick_locked(now);
                return;
            }
            // Excursions (issue 31): the enclosure off its target for longer than the plan allows.
            {
                const EnclosureTarget& target = target_;
                const double air = enclosure_air_c(), rh = enclosure_rh_pct();
                const bool off = (std::isfinite(air) && std::abs(air - target.air_c) > plan_->settle_tolerance_c) ||
                                 (std::isfinite(rh) && std::abs(rh - target.rh_pct) > plan_->settle_tolerance_rh_pct);
                if (off && !off_target_since_ns_) off_target_since_ns_ = now;
                if (off && !in_excursion_ && now - *off_target_since_ns_ > static_cast<std::int64_t>(plan_->excursion_limit_s * 1e9)) {
                    in_excursion_ = true;
                    write([trial = trial_id_](recorder::Database& db) { db.add_trial_flag(trial, flag_enclosure_excursion); });
                    event("warn", "excursion",
                          fmt::format("case {} replicate {}: the enclosure left its target for more than {:.0f} min "
                                      "({:.2f} °C for {} ± {}, {:.1f} % RH for {} ± {}); the trial is flagged, and the "
                                      "steady-state window starts again when it is back",
                                      current_->c.id, current_->replicate, plan_->excursion_limit_s / 60, air, target.air_c,
                                      plan_->settle_tolerance_c, rh, target.rh_pct, plan_->settle_tolerance_rh_pct));
                }
                if (!off) {
                    off_target_since_ns_.reset();
                    if (in_excursion_) {
                        in_excursion_ = false;
                        for (auto& r : skin_range_) r.clear();  // the final window must not hold the excursion
                        steady_since_ns_.reset();
                        acquiring_since_ns_ = now;
                        event("info", "excursion", "the enclosure is back on target: the steady-state window starts again");
                    }
                }
            }
            const double window_s = o_.config.steady_state.window_s;
            const SteadyCheck check = check_steady_window_locked(now);
            const double worst = std::isfinite(check.worst_zone_range_c) ? check.worst_zone_range_c : 0.0;
            const bool steady = check.window_steady;
            if (steady && !steady_since_ns_) {
                steady_since_ns_ = now - static_cast<std::int64_t>(window_s * 1e9);
                steady_seen_at_ns_ = now;
                write([=, trial = trial_id_, since = *steady_since_ns_](recorder::Database& db) { db.set_trial_steady(trial, since); });
                event("info", "steady", fmt::format("every zone within {:.3f} °C over the last {:.0f} min", worst, window_s / 60));
                notify_locked("steady", "info", fmt::format("trial {} (case {} replicate {}) steady", trial_id_, current_->c.id, current_->replicate),
                              fmt::format("every zone within {:.3f} °C over the last {:.0f} min", worst, window_s / 60));
            } else if (!steady && steady_since_ns_) {
                steady_since_ns_.reset();
            }
            // Stop once the duration is reached and the window has stayed steady for another minute,
            // so the analysis (5-s bins, its own window alignment) sees the same steady window.
            if (elapsed >= plan_->trial_duration_s && steady && now - steady_seen_at_ns_ >= 60'000'000'000LL) {
                enter(Stage::stopping, "trial duration reached, steady");
            } else if (elapsed > plan_->acquire_timeout_s) {
                write([=, trial = trial_id_](recorder::Database& db) { db.add_trial_flag(trial, flag_never_steady); });
                enter(Stage::stopping, fmt::format("timeout: not steady after {:.0f} min (worst zone {:.3f} °C)",
                                                   plan_->acquire_timeout_s / 60, worst));
            }
            return;
        }
        case Stage::stopping: {
            acq_->manikin().set_run(false);
            const bool physiological = loop_ != nullptr;
            loop_.reset();
            finish_trial("done", physiological || steady_since_ns_ ? "" : "never steady");
            return;
        }
        case Stage::computing: return;
    }
}

// One tick of a physiological trial: the loop gets the zones' latest readings and the
// enclosure's, and what it returns is sent (setpoints), recorded (device "model") and raised.
void LabDaemon::physiological_tick_locked(std::int64_t now) {
    const auto& zones = analysis::andi35_zone_map().zones;
    LoopInputs in;
    in.now_ns = now;
    in.zones.resize(zones.size());
    for (std::size_t z = 0; z < zones.size(); ++z) {
        const std::string prefix = fmt::format("manikin/z{:02d}.", zones[z].zone);
        const auto skin = live_.find(prefix + "skin_temp_c");
        const auto flux = live_.find(prefix + "heat_flux_w_m2");
        auto& r = in.zones[z];
        r.good = skin != live_.end() && flux != live_.end() && skin->second.quality == drivers::Quality::good &&
                 flux->second.quality == drivers::Quality::good;
        r.flagged = (skin != live_.end() && skin->second.quality == drivers::Quality::out_of_range) ||
                    (flux != live_.end() && flux->second.quality == drivers::Quality::out_of_range);
        if (skin != live_.end()) r.skin_temp_c = skin->second.value;
        if (flux != live_.end()) {
            r.heat_flux_w_m2 = flux->second.value;
            r.flux_mono_ns = flux->second.quality == drivers::Quality::good ? flux->second.mono_ns : -1;
        }
    }
    in.air_temp_c = enclosure_air_c();
    in.rh_pct = enclosure_rh_pct();
    in.wall_temp_c = enclosure_wall_c();
    const auto speed = live_.find("windsonic/air_speed_m_s");
    in.air_speed_m_s = speed != live_.end() && speed->second.quality == drivers::Quality::good ? speed->second.value : 0.0;
    LoopOutput out;
    try {
        out = loop_->tick(in);
    } catch (const std::exception& e) {
        internal_error_locked("physiological loop", e.what());
        return;
    }
    for (const auto& cmd : out.commands) {
        mc::Setpoint sp;
        sp.zone = cmd.zone;
        sp.mode = mc::ControlMode::constant_skin_temp;
        sp.value = cmd.skin_setpoint_c;
        sp.sweating = cmd.sweat_rate_g_m2_h > 0.0;
        sp.sweat_rate_g_m2_h = cmd.sweat_rate_g_m2_h;
        if (!acq_->manikin().send(sp)) {
            event("warn", "physiological", fmt::format("the manikin bus refused zone {}'s setpoint; sent again next period", cmd.zone));
            break;
        }
    }
    const std::int64_t utc = clock_->utc_ns();
    for (const auto& [channel, value] : out.model_channels)
        record_sample_locked({"model", channel, value, drivers::Quality::good, now, utc});
    for (const auto& a : out.alarms) event(a.severity, "physiological", a.message);
    if (out.fell_back) write([trial = trial_id_](recorder::Database& db) { db.add_trial_flag(trial, flag_model_fallback); });
    if (out.chamber_change)
        if (const auto why = set_chamber(out.chamber_change->chamber_temp_c, out.chamber_change->chamber_rh_pct); !why.empty())
            event("error", "physiological", fmt::format("the chamber refused the protocol's next phase: {}", why));
    if (out.finished) enter(Stage::stopping, fmt::format("the model's {:.0f} min are done", loop_->model_time_s() / 60));
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

bool LabDaemon::campaign_active() {
    std::lock_guard lk(lock_);
    return plan_.has_value() || !waiting_.empty();  // one queued begins at the next tick
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
        } else if (!current_->c.model) {
            j["trial"]["skin_setpoint_c"] = current_->c.skin_setpoint_c;
        }
        j["trial"]["zone_setpoints_c"] = std::move(zone_sp);
        if (stage_ == Stage::acquiring) {
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
            t["steady"] = steady;
            t["steady_progress"] = progress;
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
