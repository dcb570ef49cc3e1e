#pragma once
// The daemon's heart: acquisition (drivers, and the simulated lab in simulated mode), the
// recorder, and the campaign state machine. One trial goes
//   configuring -> chamber_settling -> manikin_starting -> acquiring -> stopping -> done
// (or aborted / failed / interrupted), with a timeout and a reason for every stage that can
// hang. Campaigns are cases x replicates, queued. The daemon enforces the manikin's safety
// limits itself (skin temperature, heater power, a watchdog on the manikin and chamber) and
// records every such event. Thread-safe: the control API calls in from its own thread.
#include <array>
#include <atomic>
#include <deque>
#include <functional>
#include <limits>
#include <map>
#include <memory>
#include <mutex>
#include <optional>
#include <string>
#include <variant>
#include <thread>
#include <unordered_map>
#include <utility>
#include <vector>

#include <nlohmann/json.hpp>

#include "analysis/recording.hpp"
#include "analysis/heat_loss_steady.hpp"
#include "analysis/sliding_range.hpp"
#include "daemon/acquisition.hpp"
#include "daemon/alarm_book.hpp"
#include "daemon/campaign_plan.hpp"
#include "daemon/comfort_loop.hpp"
#include "daemon/physiological_loop.hpp"
#include "daemon/config.hpp"
#include "daemon/instance_lock.hpp"
#include "store/database.hpp"
#include "store/recorder.hpp"
#include "store/trial_bins.hpp"

namespace manikind {

enum class Stage { idle, configuring, chamber_settling, manikin_starting, acquiring, stopping, computing };
const char* stage_name(Stage s);  // as in status, events and the trials table

// Trial quality flags (trials.quality_flags).
enum TrialFlag : std::int64_t {
    flag_device_gap = 1,
    flag_safety_stop = 2,
    flag_never_steady = 4,
    flag_dropped_samples = 8,
    flag_enclosure_excursion = 16,  // the enclosure left its target while acquiring (longer than excursion_limit_min)
    flag_model_fallback = 32,       // a physiological trial fell back to constant skin temperature
};

struct DaemonOptions {
    config::Config config;
    bool virtual_clock = true;   // simulated mode only: run as fast as the CPU allows
    double speed = 1.0;          // simulated real-time mode: x wall clock
};

class LabDaemon {
public:
    explicit LabDaemon(DaemonOptions options);
    ~LabDaemon();

    // Commands: an empty string when accepted, else why not (the limit or state named). A campaign
    // started while another runs is queued behind it; abort ends the running one and the queue.
    std::string start_campaign(const CampaignPlan& plan);
    // `who`: the socket peer's user, or the console; recorded with the reason in the event log.
    std::string abort(const std::string& reason, const std::string& who = "the operator");
    // How a campaign stands in the database: state, trials by state, and ok (done with every
    // planned trial done). For `manikind --exit-when-done` and `manikin campaign run --wait`.
    nlohmann::json campaign_outcome_json(const std::string& campaign);
    std::optional<std::string> running_campaign();
    std::string pause();
    std::string resume();
    // The operator did what the daemon waits for (dress the manikin: docs/daemon.md, "Operator
    // prompts"); recorded with who. An error message when nothing is waiting.
    std::string operator_continue(const std::string& who);
    std::string set_chamber(double temp_c, double rh_pct);

    nlohmann::json status_json();
    // Parts the daemon's owner adds to status_json() under `name` (the archive forwarder's state);
    // `section` is called under the daemon's lock: it must not call back into the daemon.
    void add_status_section(const std::string& name, std::function<nlohmann::json()> section);
    // An event from a part the daemon's owner runs beside it (the archive forwarder): logged,
    // stored, and an alarm when severity is warn or error. Any thread.
    void external_event(const std::string& severity, const std::string& kind, const std::string& message);
    nlohmann::json live_json();
    nlohmann::json results_json(const std::string& campaign);   // latest stored results
    // The latest stored results, or nothing while none are stored; throws for an unknown campaign.
    std::optional<nlohmann::json> latest_results_json(const std::string& campaign);

    // Alarms with a life cycle (daemon/alarm_book.hpp): the open ones (active, or returned and not
    // yet acknowledged, or shelved), oldest first; and the closed ones. Acknowledging records who
    // saw it (it does not clear the cause); a shelf hides one for at most 8 h. `who` as in abort().
    // The lab notebook (docs/daemon.md, "Notes"): appended to the database for a campaign (and
    // optionally one of its trials, by database id); author is who wrote it. Returns an error
    // message naming the field, empty when stored. notes_json: a campaign's notes, by time.
    std::string add_note(const std::string& campaign, std::optional<std::int64_t> trial_id, const std::string& kind,
                         const std::string& text, const std::string& author);
    nlohmann::json notes_json(const std::string& campaign);
    // A trial of `campaign` by the export's id ("c03-r2": case 3, replicate 2), the latest run of
    // it when the replicate was run again; or a message naming what was not found.
    std::variant<std::int64_t, std::string> trial_by_label(const std::string& campaign, const std::string& label);
    nlohmann::json alarms_json();
    nlohmann::json alarm_history_json();
    std::string acknowledge_alarm(std::int64_t id, const std::string& who = "the operator");
    std::string shelve_alarm(std::int64_t id, double duration_s, const std::string& who = "the operator");
    std::string unshelve_alarm(std::int64_t id, const std::string& who = "the operator");
    // Called (under the daemon's lock: keep it to a flag and a post) after each new sample.
    void set_sample_listener(std::function<void()> listener);
    // Called under the daemon's lock (keep it to a post: daemon/notifier.hpp) with what people away
    // from the screen may want: kind (safety, alarm_error, alarm_warn, trial_end, campaign_end,
    // steady), severity, a title and details.
    using NoticeListener = std::function<void(const std::string& kind, const std::string& severity, const std::string& title,
                                              const std::string& body, std::int64_t utc_ns)>;
    void set_notice_listener(NoticeListener listener);
    // Results so far after each trial, on their own thread. Default: in real time only.
    void set_interim_results(bool on) { interim_results_ = on; }

    // Virtual clock: steps until the queue is empty (or `max_virtual_s` passes). `on_trial` is
    // called after each trial with a one-line summary.
    void run_virtual(std::function<void(const std::string&)> on_trial = {}, double max_virtual_s = 1e12);
    void step_virtual(double dt_s);
    // Virtual clock only: steps the wall clock (UTC) by dt_ns and leaves monotonic time alone, as
    // an NTP correction or a hand-set clock does. Trial timing is monotonic: only stamps move.
    void step_wall_clock_virtual(std::int64_t dt_ns);
    // Real time: acquisition threads plus a 1-s tick thread.
    void start_realtime();
    void stop();
    bool campaign_active();
    // The stage and trial now, cheaply (status_json() measures the steady window and every device):
    // "acquiring trial 3", "idle". For a loop that reports each change.
    std::string stage_line();
    std::uint64_t committed_rows() const { return recorder_->stats().committed; }
    std::uint64_t accepted_rows() const { return recorder_->stats().accepted; }
    double virtual_time_s() const { return static_cast<double>(clock_->mono_ns()) * 1e-9; }
    // The lab's own clock (the system clock, or a simulated lab's): what its records are stamped with.
    std::int64_t lab_utc_ns() const { return clock_->utc_ns(); }

    // The daemon's read-only connection (tests read through it; every write goes to the recorder).
    // Flushed first, so that it sees every write the daemon has made.
    recorder::Database& db() {
        flush_recorder();
        return db_;
    }
    const config::Config& config() const { return o_.config; }
    // Returns when every sample recorded so far is committed (exports and tests read after it).
    void flush_recorder();
    Acquisition& acquisition() { return *acq_; }
    const std::filesystem::path& database_path() const { return db_path_; }
    // The file's readings as this run began (after a crash ring's rows were restored): the stop
    // line counts what the run stored from the file, past this mark (docs/recorder.md).
    const recorder::Database::RowMark& row_mark() const { return row_mark_; }
    std::optional<std::string> last_campaign() const { return last_campaign_; }
    // Virtual clock only: the last finished campaign as its results read it from the database, so
    // `manikin demo` need not read 9 M values back a second time (nullptr on a real clock: a lab's
    // daemon keeps no campaign in memory).
    std::shared_ptr<const analysis::Campaign> take_computed_campaign() {
        std::lock_guard lk(lock_);
        return std::exchange(computed_campaign_, nullptr);
    }
    // How many trials of the last campaign's results came from the bins kept while recording
    // (virtual clock), not read back from the database.
    std::size_t trials_binned_as_recorded() {
        std::lock_guard lk(lock_);
        return trials_binned_as_recorded_;
    }
    // Seconds since the acquisition tick last ran (real time) or the virtual clock last stepped:
    // the systemd watchdog is fed only while this stays small.
    double seconds_since_tick() const;

private:
    struct TrialJob {
        PlannedCase c;
        std::int64_t case_id = 0;
        int replicate = 0;
    };
    void on_sample(const drivers::Sample& s);
    void record_sample_locked(const drivers::Sample& s);
    void offer_row_locked(const recorder::SampleRow& row);  // into bins, then the step's batch or the recorder
    void offer_now_locked(const recorder::SampleRow& row);
    void release_step_rows_locked();
    void hold_unnamed_locked(const drivers::Sample& s);
    void retry_unnamed_locked();
    void tick_locked();     // advance_locked(), surviving a full disk
    void advance_locked();  // gaps, watchdog, then one step of the trial state machine
    void enter(Stage s, const std::string& why = {});
    // Logged and stored; warn and error are one-shot alarms (acknowledged, never "cleared").
    void event(const std::string& severity, const std::string& kind, const std::string& message);
    // A condition that lasts (a device lost, the database locked): one alarm while it lasts, keyed
    // by (kind, source); condition_cleared() logs the return (info) and clears it.
    void condition(const std::string& severity, const std::string& kind, const std::string& source, const std::string& message);
    void condition_cleared(const std::string& kind, const std::string& source, const std::string& message);
    std::int64_t now_utc_ns() const;
    void log_event(const std::string& severity, const std::string& kind, const std::string& message);  // no alarm
    void finish_trial(const std::string& state, const std::string& reason);
    void finish_campaign(const std::string& state);
    void standby_locked(const std::string& why);  // heating off, the chamber at [standby]
    void start_interim_results();
    void begin_campaign(const CampaignPlan& plan);
    void safety_stop(const std::string& why);
    void setpoint_refused(const std::string& what, const std::string& detail);
    // A full disk: heating stops, the trial and campaign end interrupted (continuable), an alarm
    // is raised; the daemon's writes wait in the recorder's line until space returns.
    void storage_stop_locked(const std::string& why);
    void retry_storage_locked();
    void storage_busy_locked(const std::string& why);
    void storage_fault_locked(const std::string& why);
    bool storage_allows_locked(const std::function<void()>& call);
    void drain_overflow_locked();
    bool flush_all_locked();  // the overflow, then the recorder: true when everything accepted is stored
    void watch_storage_locked();  // raises and clears database_locked / storage_error from the recorder's state
    void internal_error_locked(const std::string& where, const std::string& what);
    // Every write goes to the recorder, the database's one writer (store/recorder.hpp), in order.
    void write(recorder::Recorder::Job job);
    double stage_elapsed_s() const;
    std::int64_t recorded_channel(const std::string& device, const std::string& channel);  // cached database id
    // The mean of the good live readings of one enclosure quantity (the EE181 probes' air
    // temperature or RH, the wall thermocouples), from the members listed as their channels first
    // report (enclosure_members_): each tick reads a few values instead of scanning every channel.
    enum class Enclosure { air, rh, wall };
    double enclosure_mean(Enclosure quantity) const;
    void physiological_tick_locked(std::int64_t now_ns);  // acquiring, control = "physiological"
    double enclosure_air_c() const { return enclosure_mean(Enclosure::air); }
    double enclosure_rh_pct() const { return enclosure_mean(Enclosure::rh); }
    double enclosure_wall_c() const { return enclosure_mean(Enclosure::wall); }
    // Where settling stands: targets, distances, the window, an ETA (status trial.settling).
    nlohmann::json settling_json_locked(std::int64_t now_ns) const;
    // The steady-state rule's inputs now: evicts samples older than the window, then measures.
    struct SteadyCheck {
        double window_filled_fraction = 0.0;   // time acquiring / steady_state.window_s, capped at 1
        double worst_zone_range_c = std::numeric_limits<double>::quiet_NaN();   // NaN: no zone sampled yet
        int worst_zone = 0;                    // 1-based zone number, 0 when none
        bool window_steady = false;            // every zone sampled over a full window, each range < the limit
    };
    SteadyCheck check_steady_window_locked(std::int64_t now_ns);
    nlohmann::json measured_json_locked() const;

    DaemonOptions o_;
    std::filesystem::path db_path_;
    InstanceLock db_lock_;   // first: a second daemon must not touch the database at all
    std::unique_ptr<recorder::Recorder> recorder_;  // the one writer: every write goes through it
    recorder::Database db_;  // read-only: what the daemon reads back (campaigns to continue, results)
    recorder::Database::RowMark row_mark_;
    drivers::ManualClock virtual_clock_;
    drivers::SystemClock system_clock_;
    const drivers::Clock* clock_ = nullptr;
    std::unique_ptr<Acquisition> acq_;
    std::recursive_mutex lock_;

    // Campaign state.
    std::optional<CampaignPlan> plan_;
    std::deque<CampaignPlan> waiting_;   // campaigns queued behind the running one
    std::int64_t campaign_id_ = 0;
    std::deque<TrialJob> queue_;
    std::optional<TrialJob> current_;
    std::int64_t trial_id_ = 0;
    std::int64_t setup_id_ = 0;  // the set-up recorded at start (schema version 7)
    int trials_total_ = 0, trials_done_ = 0;
    Stage stage_ = Stage::idle;
    std::int64_t stage_start_ns_ = 0;
    bool paused_ = false;
    // An operator prompt of the current trial: waiting for `continue`, or answered (the trial's
    // configuring then goes on); both cleared when the next trial starts.
    std::optional<std::string> operator_prompt_;
    bool operator_answered_ = false;
    std::int64_t paused_at_ns_ = 0;
    std::int64_t paused_total_ns_ = 0;  // every pause's length, summed: the physiological loop's clock stands still by it
    bool safety_tripped_ = false;
    bool device_retry_logged_ = false;  // this stage's setpoint refusal was logged once
    bool storage_full_ = false;
    std::string storage_error_;
    std::uint64_t jobs_lost_when_full_ = 0;
    std::deque<recorder::SampleRow> overflow_;  // readings waiting for room in the recorder's queue, in order
    bool step_rows_active_ = false;             // inside step_virtual's device reads
    std::vector<recorder::SampleRow> step_rows_;  // their readings, handed over together after them
    // Readings of a channel not yet in the database while it could not be added (locked, full):
    // kept with their device/channel and added at a later tick, then recorded in order.
    std::deque<std::pair<drivers::Sample, std::int64_t>> unnamed_;  // (reading, trial id then)
    bool storage_busy_ = false;             // a write waits on a lock held past the busy timeout
    bool storage_fault_ = false;            // a write waits on a failing file system (I/O error)
    std::uint64_t storage_busy_waits_ = 0;  // how often a write found the database locked
    std::uint64_t dropped_when_full_ = 0;                  // recorder drops when the disk filled
    std::optional<std::string> last_campaign_;
    std::shared_ptr<const analysis::Campaign> computed_campaign_;  // take_computed_campaign()
    std::vector<std::string> trial_summaries_;

    // Live values and detectors.
    std::map<std::string, drivers::Sample> live_;
    std::map<std::string, std::int64_t> channel_ids_;
    // What record_sample_locked needs of a channel, found by one hash lookup of "device/channel"
    // built in a reused buffer (no allocation per reading): its live_ entry (a map node, which
    // does not move), its database id once known, its idle-log time, and what the safety and
    // steady-state checks look for in its name, decided once.
    struct ChannelSlot {
        drivers::Sample* live = nullptr;
        std::int64_t channel_id = 0;  // 0: not yet added to the database
        std::optional<std::int64_t> idle_logged_ns;  // last idle-log reading (mono)
        bool manikin = false, skin = false, heater = false, enclosure_air = false;
        int zone = 0;  // manikin zone of a skin channel ("zNN."), else 0
    };
    std::unordered_map<std::string, ChannelSlot> slots_;
    // Per Enclosure quantity, its live readings in key order (the order a scan of live_ took, so
    // the sums are the same to the bit). live_ never drops a key, so the pointers stay valid.
    std::array<std::vector<std::pair<std::string, const drivers::Sample*>>, 3> enclosure_members_;
    std::string slot_key_;  // reused per reading
    // On the virtual clock, the running campaign's trials binned as they are recorded (issue 36):
    // its results then read no reading back (CampaignReader takes a trial's bins only where they
    // hold exactly what the database does). By trial id; the current trial's also by pointer.
    std::map<std::int64_t, std::shared_ptr<recorder::TrialBins>> recorded_bins_;
    recorder::TrialBins* current_bins_ = nullptr;
    std::uint64_t recorder_losses_at_start_ = 0;  // the recorder's duplicates, drops and losses then
    std::size_t trials_binned_as_recorded_ = 0;    // of the last campaign's results
    void begin_trial_bins_locked(std::int64_t trial_id);
    std::map<std::string, std::int64_t> device_ids_;
    std::vector<analysis::SlidingRange> skin_range_;
    analysis::SlidingRange enclosure_range_;
    // Chamber settling by criteria (issue 31): on target since, the timeout's alarm said once, and
    // the air's distance from its target over the last minutes (for the ETA).
    EnclosureTarget target_;  // the running trial's enclosure target, resolved when it starts settling
    std::optional<std::int64_t> on_target_since_ns_;
    std::unique_ptr<PhysiologicalLoop> loop_;  // the running trial's, when it is physiological
    std::unique_ptr<ComfortLoop> comfort_;     // ... when it runs in comfort mode
    LoopInputs loop_inputs_locked(std::int64_t now);
    void comfort_tick_locked(std::int64_t now);
    std::optional<std::int64_t> off_target_since_ns_;  // acquiring: when the enclosure left its target
    bool in_excursion_ = false;                         // ... for longer than the plan allows
    bool settle_timeout_alarmed_ = false;
    std::deque<std::pair<std::int64_t, double>> settle_off_history_;  // (mono ns, |air - target| °C)
    std::int64_t acquiring_since_ns_ = 0;
    std::optional<std::int64_t> steady_since_ns_;
    std::int64_t steady_seen_at_ns_ = 0;
    // Clothing tests: the standards' stop rule, the whole-body heat loss steady over the window
    // (analysis/heat_loss_steady.hpp, the rule `manikin clothing` applies to the recording).
    analysis::HeatLossWindow heat_loss_window_;
    analysis::HeatLossVerdict heat_loss_verdict_;
    std::int64_t heat_loss_since_ns_ = 0;
    std::optional<std::int64_t> heat_loss_steady_since_ns_;  // held a minute, as the skin's rule is
    void sample_heat_loss_locked(std::int64_t now);
    std::map<std::string, std::int64_t> gap_since_ns_;
    std::uint64_t dropped_samples_ = 0;
    // The chamber setpoints last commanded (NaN until the first set_chamber).
    double chamber_setpoint_temp_c_ = std::numeric_limits<double>::quiet_NaN();
    double chamber_setpoint_rh_pct_ = std::numeric_limits<double>::quiet_NaN();

    AlarmBook alarms_;
    std::function<void()> sample_listener_;
    NoticeListener notice_listener_;
    void notify_locked(const std::string& kind, const std::string& severity, const std::string& title, const std::string& body);
    std::vector<std::pair<std::string, std::function<nlohmann::json()>>> status_sections_;

    std::thread tick_thread_;
    bool stop_ = false;
    std::thread interim_thread_;
    std::atomic<bool> interim_done_{true};
    std::optional<bool> interim_results_;
    std::atomic<std::int64_t> last_tick_steady_ns_{0};
};

}  // namespace manikind
