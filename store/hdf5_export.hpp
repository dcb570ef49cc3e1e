#pragma once
// `manikin export --format hdf5`: one HDF5 file per campaign (docs/formats.md, "HDF5"). The
// same table as the trial CSVs of manikin-recording/2, a group per trial, units and
// provenance as attributes, and the analysis beside the raw data. Written with Debian's
// libhdf5 (C API); read back by h5py, GNU Octave's `load` and MATLAB's `h5read`.
#include <cstdint>
#include <filesystem>
#include <memory>
#include <string>
#include <vector>

#include <nlohmann/json.hpp>

#include "analysis/analyze.hpp"
#include "analysis/recording.hpp"
#include "analysis/teq.hpp"

namespace manikind {

inline constexpr const char* kHdf5Format = "manikin-hdf5/1";
inline constexpr const char* kTeqHdf5Format = "manikin-teq-hdf5/1";

// `manikin teq --hdf5`: equivalent temperature per case (zones, regions, whole body: teq, u_A, u_B,
// u_c, k, U95, skin, q, area, verdict) and the `--json` document (docs/formats.md section 7.3).
// Writes `file` whole; UserError naming it on failure.
void write_teq_hdf5(const std::filesystem::path& file, const analysis::teq::Result& result, const nlohmann::json& doc);

// An HDF5 export written one trial at a time (memory: one trial's, issue 36). The constructor
// creates a temporary file beside `file` and writes the campaign's metadata (root attributes, zone
// map, notes: `metadata`'s trials are not read); write_trial adds a trial's group (or replaces it,
// when a trial is written again with the campaign's final channels); finish writes the results
// and renames the file into place. Destroyed unfinished (an error), it removes the temporary
// file: a failed export leaves nothing. UserError (code write_failed) naming the file on failure.
class Hdf5CampaignFile {
public:
    Hdf5CampaignFile(const std::filesystem::path& file, const analysis::Campaign& metadata);
    ~Hdf5CampaignFile();
    Hdf5CampaignFile(const Hdf5CampaignFile&) = delete;
    Hdf5CampaignFile& operator=(const Hdf5CampaignFile&) = delete;

    // `campaign` gives the zone map and the recorded channels `data` has columns for.
    void write_trial(const analysis::Campaign& campaign, const analysis::TrialInfo& info, const analysis::TrialData& data);
    // `analysis`: the campaign's analysis (written as `manikin analyze --json` gives it, and per case in columns).
    void finish(const analysis::CampaignResult& analysis);

private:
    struct Impl;
    std::unique_ptr<Impl> impl_;
};

// The whole campaign in memory at once: Hdf5CampaignFile over its trials.
// `analysis_json` is the `manikin analyze --json` document of the same campaign.
void write_campaign_hdf5(const std::filesystem::path& file, const analysis::Campaign& campaign,
                         const analysis::CampaignResult& analysis);

// Reading back one dataset or attribute (tests and tools). Throw UserError naming the file and
// the object when it is absent or of another shape.
std::vector<double> hdf5_read_doubles(const std::filesystem::path& file, const std::string& dataset);
std::vector<std::int64_t> hdf5_read_int64(const std::filesystem::path& file, const std::string& dataset);
std::vector<std::uint8_t> hdf5_read_uint8(const std::filesystem::path& file, const std::string& dataset);
std::string hdf5_read_string(const std::filesystem::path& file, const std::string& dataset);  // a scalar string dataset
std::string hdf5_read_string_attribute(const std::filesystem::path& file, const std::string& object,
                                       const std::string& attribute);

}  // namespace manikind
