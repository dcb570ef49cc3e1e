#include "analysis/reconcile/from_analysis.hpp"

#include <cmath>
#include <limits>

namespace manikind::analysis::reconcile {
double case_condition(const CaseResult& c, const std::string& channel) {
    for (const auto& e : c.conditions)
        if (e.channel == channel && std::isfinite(e.e.value)) return e.e.value;
    return std::numeric_limits<double>::quiet_NaN();
}

std::vector<CaseInput> case_inputs_from_results(const CampaignResult& result, const ZoneMap& map,
                                                std::vector<int>* skipped) {
    std::vector<CaseInput> out;
    bool heights_known = false;
    for (const auto& z : map.zones) heights_known = heights_known || z.centroid_height_m != map.zones.front().centroid_height_m;
    for (const auto& c : result.cases) {
        CaseInput in;
        in.case_id = c.case_id;
        auto& cond = in.conditions;
        cond.air_temp_c = case_condition(c, "air_temp_c");
        cond.air_rh_pct = case_condition(c, "air_rh_pct");
        if (!std::isfinite(cond.air_temp_c) || !std::isfinite(cond.air_rh_pct)) {
            if (skipped) skipped->push_back(c.case_id);
            continue;
        }
        const double wall = case_condition(c, "wall_temp_c");
        if (std::isfinite(wall)) cond.wall_temp_c = wall;
        const double speed = case_condition(c, "air_speed_m_s");
        if (std::isfinite(speed)) cond.air_speed_m_s = speed;
        cond.wettedness = c.wettedness.value_or(0.0);
        // Zone skin temperatures: the mean over the replicates used.
        std::vector<double> skin_sum(map.size(), 0.0);
        int used = 0;
        for (const auto& t : c.trials)
            if (t.included && t.zone_skin_temp_c.size() == map.size()) {
                for (std::size_t z = 0; z < map.size(); ++z) skin_sum[z] += t.zone_skin_temp_c[z];
                ++used;
            }
        for (std::size_t z = 0; z < map.size() && z < c.zones.size(); ++z) {
            const auto& zone = map.zones[z];
            const double skin = used > 0 ? skin_sum[z] / used : c.skin_setpoint_c.value_or(35.0);
            physics::twin::ZoneInput zi{zone.zone, zone.segment, zone.region, zone.area_m2, skin};
            // Geometry for the generated hypotheses (input_pattern): a height only where the map
            // gives heights (an inline map without them has every zone at 0).
            if (heights_known) zi.height_m = zone.centroid_height_m;
            zi.facing = zone.facing == "front" ? 1 : zone.facing == "back" ? -1 : 0;
            zi.side = zone.side == "l" ? -1 : zone.side == "r" ? 1 : 0;
            // The room the campaign stated for this case ([[cases.local]]): the twin meets each
            // zone where it is, not only at the probes (issue 65).
            if (c.local.size() == map.size()) zi.local = c.local[z];
            cond.zones.push_back(std::move(zi));
            in.q_exp_w_m2.push_back(c.zones[z].q.value);
            in.expanded_u_w_m2.push_back(c.zones[z].q.U);
            in.coverage_k.push_back(c.zones[z].q.k);
            in.zone_names.push_back(zone.name);
            in.sides.push_back(zone.side);
            in.heights_m.push_back(zone.centroid_height_m);
        }
        // The replicates, each with its own recorded conditions (the noise model's random part).
        for (const auto& t : c.trials) {
            if (!t.included || t.zone_q_w_m2.size() != map.size() || t.zone_skin_temp_c.size() != map.size()) continue;
            if (!std::isfinite(t.air_temp_c) || !std::isfinite(t.air_rh_pct)) continue;
            TrialInput trial;
            trial.conditions = cond;
            trial.conditions.air_temp_c = t.air_temp_c;
            trial.conditions.air_rh_pct = t.air_rh_pct;
            if (std::isfinite(t.wall_temp_c)) trial.conditions.wall_temp_c = t.wall_temp_c;
            if (std::isfinite(t.air_speed_m_s)) trial.conditions.air_speed_m_s = t.air_speed_m_s;
            for (std::size_t z = 0; z < trial.conditions.zones.size(); ++z) trial.conditions.zones[z].skin_temp_c = t.zone_skin_temp_c[z];
            trial.q_w_m2.assign(t.zone_q_w_m2.begin(), t.zone_q_w_m2.begin() + static_cast<long>(trial.conditions.zones.size()));
            trial.id = t.id;
            if (t.steady.zone_flux_drift_w_m2.size() >= trial.conditions.zones.size())
                trial.flux_drift_w_m2.assign(t.steady.zone_flux_drift_w_m2.begin(),
                                             t.steady.zone_flux_drift_w_m2.begin() + static_cast<long>(trial.conditions.zones.size()));
            in.trials.push_back(std::move(trial));
        }
        out.push_back(std::move(in));
    }
    return out;
}

}  // namespace manikind::analysis::reconcile
