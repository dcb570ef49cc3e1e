#pragma once
// `manikin export --format hdf5`: one HDF5 file per campaign (docs/formats.md, "HDF5"). The
// same table as the trial CSVs of manikin-recording/2, a group per trial, units and
// provenance as attributes, and the analysis beside the raw data. Written with Debian's
// libhdf5 (C API); read back by h5py, GNU Octave's `load` and MATLAB's `h5read`.
#include <cstdint>
#include <filesystem>
#include <string>
#include <vector>

#include <nlohmann/json.hpp>

#include "analysis/recording.hpp"

namespace manikind {

inline constexpr const char* kHdf5Format = "manikin-hdf5/1";

// Writes `file` (via a temporary file renamed into place: a failed export leaves nothing).
// `analysis_json` is the `manikin analyze --json` document of the same campaign.
void write_campaign_hdf5(const std::filesystem::path& file, const analysis::Campaign& campaign,
                         const nlohmann::json& analysis_json);

// Reading back one dataset or attribute (tests and tools). Throw UserError naming the file and
// the object when it is absent or of another shape.
std::vector<double> hdf5_read_doubles(const std::filesystem::path& file, const std::string& dataset);
std::vector<std::int64_t> hdf5_read_int64(const std::filesystem::path& file, const std::string& dataset);
std::vector<std::uint8_t> hdf5_read_uint8(const std::filesystem::path& file, const std::string& dataset);
std::string hdf5_read_string(const std::filesystem::path& file, const std::string& dataset);  // a scalar string dataset
std::string hdf5_read_string_attribute(const std::filesystem::path& file, const std::string& object,
                                       const std::string& attribute);

}  // namespace manikind
