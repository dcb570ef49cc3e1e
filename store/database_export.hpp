#pragma once
// From the recorder's database to the interchange format (analysis::Campaign): each finished
// trial's samples from the manikin's start to the trial's end, binned on a 5-s grid (Text S3.2
// samples every 5 s), good samples only. Air temperature and humidity are the mean of the EE181
// probes, wall temperature the mean of the thermocouples, air speed the WindSonic's.
#include <filesystem>
#include <functional>
#include <map>
#include <memory>
#include <string>
#include <vector>

#include "analysis/recording.hpp"
#include "store/database.hpp"
#include "store/trial_bins.hpp"

namespace manikind {

// A campaign read out of the database one trial at a time, so an export's memory is one trial's,
// whatever the campaign's length (issue 36). The constructor reads everything but the samples
// and throws UserError when the campaign is unknown or has no finished trial (with
// `include_running`: no finished or running one); a trial still acquiring is exported from the
// manikin's start to its last committed reading, marked `partial`.
class CampaignReader {
public:
    CampaignReader(recorder::Database& db, const std::string& campaign_name, double sample_period_s = 5.0,
                   bool include_running = false);
    ~CampaignReader();
    CampaignReader(const CampaignReader&) = delete;
    CampaignReader& operator=(const CampaignReader&) = delete;

    // The campaign with every exported trial's info and no samples (`trials[i].data` empty).
    // `channels` holds the channels recorded in the trials read so far, in the database's order.
    const analysis::Campaign& campaign() const { return campaign_; }
    analysis::Campaign& campaign() { return campaign_; }
    std::size_t trial_count() const;

    // Trial i's samples, read and binned now, with a column for each of campaign().channels as
    // they stand after this call. A channel first recorded in this trial is added to them, so a
    // trial read before lacks it: channel_generation() counts the changes, and a trial read at
    // an earlier generation is read again once all are read (every trial then has every column).
    analysis::TrialData read(std::size_t i);
    std::size_t channel_generation() const { return generation_; }

    // Trials binned as they were recorded, by trial id (the daemon on the virtual clock, issue 36):
    // read() takes a trial's rows from its bins instead of the database when they cover exactly
    // what is stored (the same start and period, as many rows offered as the trial holds), else
    // it reads the trial back as usual. A trial's bins are let go once read (a trial read again
    // is read from the database). trials_from_recording() counts the reads so spared.
    using RecordedBins = std::map<std::int64_t, std::shared_ptr<const recorder::TrialBins>>;
    void use_recorded_bins(RecordedBins bins) { recorded_bins_ = std::move(bins); }
    std::size_t trials_from_recording() const { return from_recording_; }

private:
    struct Span;
    recorder::Database& db_;
    double period_s_;
    analysis::Campaign campaign_;
    std::vector<Span> spans_;
    std::vector<recorder::ChannelRow> all_channels_;
    std::vector<std::size_t> index_of_id_;          // channel id -> index into all_channels_
    std::map<std::string, std::size_t> index_of_key_; // "device/name" -> index into all_channels_
    std::vector<bool> recorded_;                     // by index into all_channels_: seen in a trial read
    std::size_t generation_ = 0;
    RecordedBins recorded_bins_;
    std::size_t from_recording_ = 0;
    const recorder::TrialBins* usable_bins(std::size_t i);
};

// Throws UserError when the campaign is unknown or has no finished trial (with `include_running`:
// no finished or running one). `include_running`: a trial still acquiring is exported too, from the
// manikin's start to its last committed reading, marked `partial` (an export taken mid-campaign).
analysis::Campaign campaign_from_database(recorder::Database& db, const std::string& campaign_name,
                                          double sample_period_s = 5.0, bool include_running = false);
// Every trial of the reader's campaign read into it (campaign_from_database's work).
analysis::Campaign read_whole_campaign(CampaignReader& reader);

// A case's number as the export names it: the plan's id, else its position + 1 (also when the
// stored conditions are not a JSON object).
int case_number_of(const recorder::CaseRow& c);
// The export's id of a trial: "c01-r2".
std::string exported_trial_id(int case_number, std::int64_t replicate);
// The export's id of every trial of a campaign, by the trial's database id.
std::map<std::int64_t, std::string> exported_trial_ids(recorder::Database& db, std::int64_t campaign_id);

// `manikin export`: writes campaign.json and trials/*.csv into `folder`.
void export_campaign(recorder::Database& db, const std::string& campaign_name, const std::filesystem::path& folder);

// What a streaming export wrote: rows in all, each trial's last t_s (in the reader's order), and
// how many trials were written twice because a later one added a channel.
struct ExportCounts {
    std::size_t rows = 0;
    std::vector<double> last_t_s;
    std::size_t rewritten = 0;
};
// Called after each trial: (trials done, trials in all).
using ExportProgress = std::function<void(std::size_t, std::size_t)>;

// Each trial read once and handed to `visit(i, data, again = false)`; then every trial read before
// a later one added a channel is read anew and handed again (`again` = true), so what a visitor
// keeps of the last visit of each trial has every column. Rows and last t_s count the first visits.
using TrialVisitor = std::function<void(std::size_t, analysis::TrialData&&, bool)>;  // the data is the visitor's to keep
ExportCounts stream_trials(CampaignReader& reader, const TrialVisitor& visit, const ExportProgress& progress = {});

// The CSV export one trial at a time: each trial's CSV written as it is read, campaign.json last.
ExportCounts export_campaign_csv(CampaignReader& reader, const std::filesystem::path& folder,
                                 const ExportProgress& progress = {});

}  // namespace manikind
