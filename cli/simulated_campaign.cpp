#include "cli/simulated_campaign.hpp"

namespace manikind {

analysis::Campaign simulate_campaign(const std::string& name, const std::vector<sim::CampaignCase>& cases,
                                     const sim::GeneratorOptions& options, int* unsteady_trials) {
    const analysis::ZoneMap& map = analysis::andi35_zone_map();
    std::vector<sim::ZoneSpec> zones;
    for (const auto& z : map.zones) zones.push_back({{z.zone, z.segment, z.region, z.area_m2, 35.0}, z.name});
    auto trials = sim::generate_campaign(cases, zones, options);

    analysis::Campaign c;
    c.name = name;
    c.zone_map = map;
    c.instruments = analysis::default_instrument_specs();
    int unsteady = 0;
    for (auto& t : trials) {
        analysis::Trial tr;
        tr.info.id = t.id;
        tr.info.case_id = t.case_id;
        tr.info.replicate = t.replicate;
        tr.info.file = "trials/" + t.id + ".csv";
        tr.info.skin_setpoint_c = t.conditions.skin_setpoint_c;
        tr.info.wettedness = t.conditions.wettedness;
        tr.info.chamber_setpoint_temp_c = t.conditions.chamber_temp_c;
        tr.info.chamber_setpoint_rh_pct = t.conditions.chamber_rh_pct;
        tr.info.started_utc = t.started_utc;
        tr.data.t_s = std::move(t.t_s);
        tr.data.air_temp_c = std::move(t.air_temp_c);
        tr.data.air_rh_pct = std::move(t.air_rh_pct);
        tr.data.air_speed_m_s = std::move(t.air_speed_m_s);
        tr.data.wall_temp_c = std::move(t.wall_temp_c);
        tr.data.skin_temp_c = std::move(t.skin_temp_c);
        tr.data.heat_flux_w_m2 = std::move(t.heat_flux_w_m2);
        unsteady += t.unsteady ? 1 : 0;
        c.trials.push_back(std::move(tr));
    }
    if (unsteady_trials) *unsteady_trials = unsteady;
    return c;
}

}  // namespace manikind
