// LabDaemon's sample path and storage: each reading from a driver to the recorder (the live
// slots, readings held while the recorder's queue is full), and what the daemon does while the
// disk is full, locked or failing. The rest of LabDaemon: lab_daemon.cpp.
#include "daemon/lab_daemon.hpp"

#include <fmt/format.h>
#include <spdlog/spdlog.h>

#include <algorithm>

namespace manikind {

namespace {
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

}  // namespace manikind
