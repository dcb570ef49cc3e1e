#include "analysis/reconcile/results_parity.hpp"

#include "analysis/reconcile/from_analysis.hpp"
#include "analysis/zone_map.hpp"
#include "analysis/reconcile/twin_store.hpp"
#include "physics/twin/twin.hpp"

namespace manikind {

nlohmann::json twin_parity_json(const analysis::CampaignResult& result) {
    nlohmann::json points = nlohmann::json::array();
    const auto cases = analysis::reconcile::case_inputs_from_results(result, analysis::andi35_zone_map());
    const auto twin = twin_store::load_twin_version("baseline");
    for (const auto& input : cases) {
        const auto measured = std::find_if(result.cases.begin(), result.cases.end(),
                                           [&](const analysis::CaseResult& c) { return c.case_id == input.case_id; });
        if (measured == result.cases.end()) continue;
        std::vector<int> zone_ids;
        for (const auto& z : input.conditions.zones) zone_ids.push_back(z.zone);
        const auto fluxes = physics::twin::predict(twin, input.conditions);
        points.push_back({{"case", input.case_id},
                          {"twin_w_m2", physics::twin::area_weighted_mean_w_m2(fluxes, input.conditions.zones, zone_ids)},
                          {"measured_w_m2", measured->whole_body.q.value},
                          {"U_w_m2", measured->whole_body.q.U}});
    }
    return points;
}

}  // namespace manikind
