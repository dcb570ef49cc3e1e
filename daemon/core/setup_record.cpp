#include "daemon/core/setup_record.hpp"

#include <nlohmann/json.hpp>

#include "daemon/core/register_map.hpp"

namespace manikind {

recorder::Setup setup_of(const config::Config& config) {
    nlohmann::ordered_json calibration;
    auto& instruments = calibration["instruments"] = nlohmann::ordered_json::object();
    for (const auto& [channel, spec] : config.instruments)  // a std::map: sorted, so the text is stable
        instruments[channel] = {{"accuracy", spec.accuracy},
                                {"accuracy_of_reading", spec.accuracy_of_reading},
                                {"distribution", spec.distribution}};
    auto& maps = calibration["register_maps"] = nlohmann::ordered_json::object();
    for (const auto& [device, modbus] :
         {std::pair{"chamber", &config.devices.chamber}, std::pair{"datalogger", &config.devices.datalogger}})
        maps[device] = {{"setting", modbus->register_map},
                        {"toml", register_map_text(modbus->register_map, device, config.source_dir)}};
    calibration["steady_state"] = {{"window_s", config.steady_state.window_s},
                                   {"max_skin_fluctuation_c", config.steady_state.max_skin_fluctuation_c}};
    return {config.lab_name, config.chamber, config.manikin, calibration.dump(), config.source_text};
}

}  // namespace manikind
