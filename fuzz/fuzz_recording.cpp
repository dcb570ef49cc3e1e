// libFuzzer target for the recording reader (analysis/recording.hpp): the input up to its first
// NUL byte is campaign.json, the rest the trial CSV every trial of it may name ("trials/t.csv").
// The CSV alone also goes through read_trial_csv with a two-zone map; a campaign read is also
// replayed as a physiological trial where it has the model's channels. Only InputError may escape.
#include <unistd.h>

#include <cstdint>
#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <string>
#include <string_view>

#include "analysis/input_error.hpp"
#include "analysis/physio.hpp"
#include "analysis/recording.hpp"
#include "analysis/zone_map.hpp"

namespace fs = std::filesystem;
using namespace manikind::analysis;

namespace {

// One folder per fuzzing process, rewritten for every input.
const fs::path& campaign_folder() {
    static const fs::path folder = [] {
        const fs::path f = fs::temp_directory_path() / ("manikind-fuzz-recording-" + std::to_string(::getpid()));
        fs::create_directories(f / "trials");
        return f;
    }();
    return folder;
}

void write_file(const fs::path& path, std::string_view text) {
    std::ofstream(path, std::ios::binary | std::ios::trunc).write(text.data(), static_cast<std::streamsize>(text.size()));
}

ZoneMap two_zone_map() {
    ZoneMap map;
    map.name = "inline";
    map.zones.push_back({1, "front", "torso", "torso", "c", 0.1, 1.2});
    map.zones.push_back({2, "back", "torso", "torso", "c", 0.3, 1.2});
    return map;
}

}  // namespace

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
    const std::string_view input(reinterpret_cast<const char*>(data), size);
    const auto nul = input.find('\0');
    const std::string_view json = nul == std::string_view::npos ? std::string_view{} : input.substr(0, nul);
    const std::string_view csv = nul == std::string_view::npos ? input : input.substr(nul + 1);

    const fs::path& folder = campaign_folder();
    write_file(folder / "trials" / "t.csv", csv);
    try {
        static const ZoneMap map = two_zone_map();
        (void)read_trial_csv(folder / "trials" / "t.csv", map, "t.csv");
    } catch (const InputError&) {
    }
    if (nul != std::string_view::npos) {
        write_file(folder / "campaign.json", json);
        try {
            const Campaign campaign = read_campaign(folder);
            // A physiological trial's model channels are replayed (analysis/physio.hpp): hostile
            // values must end in InputError, never a crash or another exception.
            physio::Options few;
            few.draws = 20;
            (void)physio::compute(campaign, few);
        } catch (const InputError&) {
        }
    }
    return 0;
}
