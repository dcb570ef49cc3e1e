#pragma once
// A campaign in memory, as read from or written to the interchange format
// `manikin-recording/2` (docs/formats.md section 1): campaign.json + trials/<id>.csv.
// Version 1 (no UTC column, no per-instrument channels) is still read.
//
// Samples are stored column-wise (one vector per channel) because everything downstream
// (steady state, window means) walks one channel over time. Empty CSV cells are NaN.
#include <cstdint>
#include <filesystem>
#include <limits>
#include <map>
#include <optional>
#include <random>
#include <string>
#include <string_view>
#include <vector>

#include <nlohmann/json_fwd.hpp>

#include "analysis/local_room.hpp"
#include "analysis/zone_map.hpp"
#include "physics/sign_convention.hpp"

namespace manikind::analysis {

// A missing value (no reading, no estimate) in the analysis' tables and reports.
inline constexpr double kNaN = std::numeric_limits<double>::quiet_NaN();

inline constexpr const char* kRecordingFormat = "manikin-recording/2";
inline constexpr const char* kRecordingFormatV1 = "manikin-recording/1";

// One sign for heat flux in every file and command (physics/sign_convention.hpp).
inline constexpr const char* kHeatFluxSign = physics::heat_flux_sign;

// A Type B specification: the manufacturer's limit ±(accuracy + accuracy_of_reading x |reading|).
enum class Distribution {
    rectangular,   // limits of a uniform distribution: u = a / sqrt(3) (GUM 4.3.7)
    normal_k2,     // an expanded uncertainty stated at k = 2 (95 %): u = a / 2
    triangular,    // u = a / sqrt(6) (GUM 4.3.9)
};

struct InstrumentSpec {
    double accuracy = 0.0;             // in the channel's unit
    double accuracy_of_reading = 0.0;  // fraction of |reading|
    Distribution distribution = Distribution::rectangular;

    // Half-width of the limit at this reading, in the channel's unit.
    double limit(double reading) const;
    // Standard uncertainty u_B at this reading.
    double standard_uncertainty(double reading) const;
};

const char* to_string(Distribution d);
// One draw of an instrument's error in units of its limit, from the spec's distribution (a k = 2
// limit: sd 1/2): Monte Carlo Type B multiplies it by limit(reading) (clothing, physio).
double standardised_error_draw(Distribution d, std::mt19937_64& rng);
std::optional<Distribution> distribution_from_string(const std::string& s);

// The channels that carry Type B specs, by the names used in campaign.json `instruments`.
inline constexpr const char* kInstrumentChannels[] = {"air_temp_c", "air_rh_pct", "air_speed_m_s",
                                                      "wall_temp_c", "skin_temp_c", "heat_flux_w_m2"};

// Defaults when campaign.json leaves a channel out: Tables S1-S2 for the air and wall
// sensors (EE181 ±0.2 °C and ±(1.4 + 0.01 RH) %, hot-wire ±0.02 m/s, Type-T ±0.5 °C); the
// manikin's own skin-temperature and heat-flux specs are not in the paper and come from the
// project's configuration (config/manikind.toml: ±0.1 °C, ±(1.0 W/m² + 3 % of reading)).
std::map<std::string, InstrumentSpec> default_instrument_specs();

struct TrialInfo {
    std::string id;
    int case_id = 0;
    int replicate = 0;
    std::string file;                  // relative to the campaign folder
    std::optional<double> skin_setpoint_c;
    std::optional<double> wettedness;  // "wettedness", else 1 if "wet" is true, 0 if false
    std::optional<double> chamber_setpoint_temp_c;
    std::optional<double> chamber_setpoint_rh_pct;
    std::string started_utc;
    std::optional<std::int64_t> t0_utc_ns;  // wall time at t_s = 0 (format 2: "t0_utc")
    std::string ensemble;              // clothing worn: an id of Campaign::ensembles, "nude", or empty (not a clothing test)
    std::string test;                  // "insulation", "evaporative", or empty
    std::string control;               // "physiological" (the thermoregulation model's control), or empty
    LocalRoom local;                   // the room where not uniform, per zone of the map (campaign's [[cases.local]])
    bool partial = false;              // exported while running: up to its last committed reading ("partial": true)
};

// A clothing ensemble a campaign's trials wear (docs/formats.md, "ensembles").
struct Ensemble {
    std::string description;
    std::optional<double> fcl;         // clothing area factor; absent: ISO 9920's estimate from the insulation
    std::optional<double> fcl_u;       // a given fcl's standard uncertainty (the lab's measurement); enters U of Icl, Recl
};

// A lab-notebook entry carried with the recording (docs/formats.md, "notes"): who wrote what, when,
// about the campaign or one of its trials.
struct Note {
    std::int64_t utc_ns = 0;
    std::string author;
    std::string kind = "comment";      // comment, operator, ensemble, garment
    std::string text;
    std::string trial;                 // a trial's id in this campaign; empty: the campaign as a whole
};
// The kinds a note may have, and the longest text a note may carry (bytes).
bool is_note_kind(std::string_view kind);
constexpr std::size_t kMaxNoteBytes = 4000;

// One instrument channel as recorded (format 2), e.g. device "datalogger", name
// "ee181_1.air_temp_c". In the trial CSV its column is "<device>.<name>", followed by
// "<device>.<name>.q" with the quality code of each value.
struct RecordedChannel {
    std::string device;
    std::string name;
    std::string unit;
    std::string column() const { return device + "." + name; }
};

// Quality codes in ".q" columns: the recorder's (0 good, 1 stale, 2 out of range, 3
// communication error); kNoSample where no sample fell in the row's interval (an empty cell).
inline constexpr std::uint8_t kNoSample = 255;

// One trial's samples. `skin_temp_c[z]` and `heat_flux_w_m2[z]` are indexed like the zone
// map (zone number - 1); all vectors have `t_s.size()` entries.
struct TrialData {
    std::vector<double> t_s;
    std::vector<double> air_temp_c;
    std::vector<double> air_rh_pct;
    std::vector<double> air_speed_m_s;   // empty when the file has no such column
    std::vector<double> wall_temp_c;     // empty when the file has no such column
    std::vector<std::vector<double>> skin_temp_c;
    std::vector<std::vector<double>> heat_flux_w_m2;
    std::vector<std::int64_t> utc_ns;    // format 2 "utc" column; empty when the file has none
    // Per recorded channel, indexed like Campaign::channels (empty vectors in format 1).
    std::vector<std::vector<double>> channel_values;
    std::vector<std::vector<std::uint8_t>> channel_quality;

    std::size_t rows() const { return t_s.size(); }
};

struct Trial {
    TrialInfo info;
    TrialData data;
};

struct Campaign {
    std::string name;
    ZoneMap zone_map;
    bool zone_map_inline = false;      // written back inline rather than by name
    std::map<std::string, InstrumentSpec> instruments;  // every channel, defaults filled in
    std::vector<RecordedChannel> channels;                // format 2: every instrument channel in the CSVs
    std::map<std::string, std::string> provenance;        // program, database, twin_version, config_sha256, ...
    std::map<std::string, Ensemble> ensembles;            // clothing tests: what the trials wear, by id
    // Clothing tests: the standard each test followed, with its edition, as the campaign chose it
    // ("insulation" -> "ISO 15831:2004", "evaporative" -> "ASTM F2370-16"; docs/formats.md).
    std::map<std::string, std::string> standards;
    std::vector<Note> notes;                              // the lab notebook, by time
    std::vector<Trial> trials;
    std::vector<std::string> warnings; // unknown keys and the like, with the file named

    // The spec of a channel (air_temp_c, heat_flux_w_m2, ...); a zero spec when it has none.
    InstrumentSpec instrument(const std::string& channel) const;
};

struct ReadOptions {
    // Channels missing from campaign.json take these (the CLI passes the configured ones).
    std::map<std::string, InstrumentSpec> default_instruments = default_instrument_specs();
};

// Reads a whole campaign folder. The CSVs are streamed in fixed-size chunks and parsed with
// std::from_chars. Everything is parsed into local structures first; on any error an
// InputError (file, line, column, field) is thrown and nothing is returned, so a campaign
// is never half-imported.
Campaign read_campaign(const std::filesystem::path& folder, const ReadOptions& options = {});

// The two halves of read_campaign, for reading one trial at a time (memory bounded by one
// trial, not the campaign). read_campaign_metadata reads and checks campaign.json exactly as
// read_campaign does (zone map, instruments, channels, provenance, warnings, the trial list;
// each trial file is checked to be a regular file inside the folder) but leaves every
// `trials[i].data` empty. read_trial_data then parses one trial's CSV with read_campaign's
// checks and messages; `metadata` is what read_campaign_metadata returned for `folder`.
Campaign read_campaign_metadata(const std::filesystem::path& folder, const ReadOptions& options = {});
TrialData read_trial_data(const std::filesystem::path& folder, const Campaign& metadata, const TrialInfo& info);

// Parses one trial CSV (exposed for tests and tools). `display_name` is used in messages.
// `channels` are the recorded channels campaign.json declares (format 2).
TrialData read_trial_csv(const std::filesystem::path& file, const ZoneMap& map, const std::string& display_name,
                         const std::vector<RecordedChannel>& channels = {});

// ISO 8601 UTC with milliseconds ("2026-11-24T01:35:07.250Z") and back; nullopt when malformed.
std::string iso_utc_ms(std::int64_t utc_ns);
std::optional<std::int64_t> parse_iso_utc(std::string_view text);

// campaign.json's `ensembles` object: {"<id>": {"description": ..., "fcl": ...}} (fcl when given).
nlohmann::json ensembles_json(const std::map<std::string, Ensemble>& ensembles);

// campaign.json's `notes` array: [{"utc", "author", "kind", "text", "trial"?}] in time order.
nlohmann::json notes_json(const std::vector<Note>& notes);

// Writes campaign.json and trials/<id>.csv into `folder` (created if needed). Numbers are
// written with the shortest representation that reads back to the same double, so a
// write/read round trip is exact. NaN samples are written as empty cells.
void write_campaign(const std::filesystem::path& folder, const Campaign& campaign);

// write_campaign's two halves, for writing one trial at a time: a trial's CSV (at its info's
// `file`, else trials/<id>.csv), with a column pair for each of `campaign.channels`; and
// campaign.json from `campaign`'s metadata and trial infos (their data unread), written last.
void write_trial_file(const std::filesystem::path& folder, const Campaign& campaign, const TrialInfo& info,
                      const TrialData& data);
void write_campaign_json(const std::filesystem::path& folder, const Campaign& campaign);

// Column names of the trial CSV for a map, in the order the writer uses.
std::vector<std::string> trial_csv_columns(const ZoneMap& map, bool with_air_speed, bool with_wall_temp);

}  // namespace manikind::analysis
