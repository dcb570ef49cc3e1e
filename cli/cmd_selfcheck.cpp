// `manikin selfcheck`: recomputes the paper's headline numbers with the physics library and
// prints them beside the printed values, so a user can see at a glance that the build is sound.
#include <cmath>
#include <cstdio>
#include <string>
#include <vector>

#include <fmt/core.h>
#include <nlohmann/json.hpp>

#include "cli/commands.hpp"
#include "base/user_error.hpp"
#include "physics/buoyancy.hpp"
#include "physics/convection.hpp"
#include "physics/paper_cfd_table.hpp"
#include "physics/psychrometrics.hpp"
#include "physics/threshold_map.hpp"

namespace manikind::cli {
namespace {

namespace ph = manikind::physics;

struct Check {
    std::string what;
    std::string source;
    double paper = 0.0;
    double ours = 0.0;
    double tolerance = 0.0;
    std::string unit;
    bool pass() const { return std::abs(ours - paper) <= tolerance; }
};

ph::SkinAirState wet(double skin_c, double air_c, double rh_pct) {
    ph::SkinAirState s;
    s.skin_temp_c = skin_c;
    s.air_temp_c = air_c;
    s.air_rh_pct = rh_pct;
    return s;
}

std::vector<Check> run_checks() {
    std::vector<Check> checks;
    const double rho10 = ph::moist_air_density_kg_m3(35.0, ph::vapour_pressure_pa(35.0, 10.0));
    const double rho_sat = ph::moist_air_density_kg_m3(35.0, ph::vapour_pressure_pa(35.0, 100.0));
    checks.push_back({"saturated vs 10 % RH air at 35 C, lighter by", "Introduction", 1.9,
                      100.0 * (rho10 - rho_sat) / rho10, 0.05, "%"});
    checks.push_back({"beta_C alpha/(beta_T D), all at 35 C", "Discussion", 145.7,
                      ph::coupling_coefficient(wet(35.0, 35.0, 10.0)), 0.5, ""});
    checks.push_back({"beta_C alpha/(beta_T D), 37 C skin", "Discussion", 146.9,
                      ph::coupling_coefficient(wet(37.0, 35.0, 10.0)), 0.5, ""});
    checks.push_back({"stagnation air temperature, 10 % RH, 35 C wet skin", "Introduction", 41.0,
                      ph::stagnation_air_temp_c(10.0, 35.0).value_or(NAN), 0.5, "°C"});

    double sum = 0.0, sum_abs = 0.0, sum_sq = 0.0;
    int n = 0;
    for (const auto& c : ph::paper_cfd_cases()) {
        const auto b = ph::buoyancy(wet(ph::cfd_skin_temp_c, c.air_temp_c, c.air_rh_pct));
        const double e = 100.0 * (c.h_sim_w_m2k - ph::h_eq8_w_m2k(b.dt_c, b.dc_kg_m3)) / c.h_sim_w_m2k;
        sum += e;
        sum_abs += std::abs(e);
        sum_sq += e * e;
        ++n;
    }
    checks.push_back({"Eq. 8 vs CFD table: mean error", "Discussion", -2.6, sum / n, 0.1, "%"});
    checks.push_back({"Eq. 8 vs CFD table: mean absolute error", "Discussion", 7.7, sum_abs / n, 0.2, "%"});
    checks.push_back({"Eq. 8 vs CFD table: RMS error", "Discussion", 13.3, std::sqrt(sum_sq / n), 0.3, "%"});
    checks.push_back({"h_c/h_F limit for h_mix/h_F <= 1.05 (Eq. 9)", "Discussion", 0.54,
                      ph::max_free_to_forced_ratio(1.05), 0.005, ""});
    checks.push_back({"h_c/h_F limit for h_mix/h_F <= 1.1 (Eq. 9)", "Discussion", 0.69,
                      ph::max_free_to_forced_ratio(1.1), 0.005, ""});
    checks.push_back({"minimum threshold air speed (1 C x 10 % grid)", "Fig. 3C", 0.03,
                      ph::minimum_threshold_on_grid(ph::ThresholdGrid{}).speed_m_s, 0.005, "m/s"});
    return checks;
}

}  // namespace

void add_selfcheck_command(CLI::App& app) {
    auto json = std::make_shared<bool>(false);
    auto* cmd = app.add_subcommand("selfcheck", "Recompute the paper's headline numbers and compare with the printed values");
    cmd->add_flag("--json", *json, "Print one JSON document");
    cmd->footer("Exit status 5 when any number leaves its tolerance (docs/cli.md); under --json the table is then\n"
                "the error's \"details\".");
    cmd->callback([json] {
        const auto checks = run_checks();
        int failed = 0;
        nlohmann::json out = nlohmann::json::array();
        if (!*json) std::printf("%-52s %-13s %9s %9s %8s  %s\n", "check", "source", "paper", "ours", "tol", "");
        for (const auto& c : checks) {
            failed += c.pass() ? 0 : 1;
            if (*json) {
                out.push_back({{"check", c.what}, {"source", c.source}, {"paper", c.paper},
                               {"ours", std::isfinite(c.ours) ? nlohmann::json(c.ours) : nlohmann::json()},
                               {"tolerance", c.tolerance}, {"unit", c.unit}, {"pass", c.pass()}});
            } else {
                std::printf("%-52s %-13s %9.4g %9.4g %8.3g  %s %s\n", c.what.c_str(), c.source.c_str(), c.paper,
                            c.ours, c.tolerance, c.unit.c_str(), c.pass() ? "ok" : "MISMATCH");
            }
        }
        const std::size_t passed = checks.size() - static_cast<std::size_t>(failed);
        const nlohmann::json document = {{"checks", out}, {"passed", passed}, {"failed", failed}};
        if (!*json) std::printf("\n%zu passed, %d failed\n", passed, failed);
        if (failed > 0)
            throw UserError::check_failed(fmt::format("{} of {} checks out of tolerance", failed, checks.size()),
                                          *json ? document : nlohmann::json());
        if (*json) std::printf("%s\n", document.dump(2).c_str());
    });
}

}  // namespace manikind::cli
