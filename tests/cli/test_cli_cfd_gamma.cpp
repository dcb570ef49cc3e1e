// `manikin physics cfd-gamma --json`: the Eq. 7 / Eq. S8-shape gamma fits on Tables S8-S10, as a user runs them.
#include <catch2/catch.hpp>

#include <nlohmann/json.hpp>

#include "analysis/reconcile/cfd_forms.hpp"
#include "tests/cli/run_cli.hpp"
#include "tests/physics/paper_csv.hpp"

using manikind::test::run_manikin;
namespace rc = manikind::analysis::reconcile;

TEST_CASE("cli: physics cfd-gamma --json fits Eq. 7 to Tables S8-S10 as the library does on the shipped CSV", "[cli]") {
    const auto r = run_manikin("physics cfd-gamma --json");
    REQUIRE(r.exit_code == 0);
    const auto j = nlohmann::json::parse(r.out);
    std::vector<rc::CfdHObservation> obs;
    for (const auto& row : manikind::test::read_paper_csv("cfd_whole_body_cases.csv"))
        obs.push_back({std::stoi(row.at("case")), manikind::test::num(row, "t_air_c"), manikind::test::num(row, "rh_air_pct"),
                       manikind::test::num(row, "t_air_c") + manikind::test::num(row, "dt_sk_air_c"),
                       manikind::test::num(row, "h_sim_w_m2k")});
    const auto lib = rc::fit_cfd_gamma_forms(obs);
    CHECK(j.at("n_points").get<int>() == 90);
    REQUIRE(j.at("fits").size() == lib.fits.size());
    for (std::size_t i = 0; i < lib.fits.size(); ++i) {
        CHECK(j.at("fits")[i].at("gamma_k_m3_kg").get<double>() == Approx(lib.fits[i].gamma_k_m3_kg));
        CHECK(j.at("fits")[i].at("gamma_se_k_m3_kg").get<double>() == Approx(lib.fits[i].gamma_se_k_m3_kg));
        CHECK(j.at("fits")[i].at("rmse_pct").get<double>() == Approx(lib.fits[i].rmse_pct));
    }
    CHECK(j.at("gamma_combined_k_m3_kg").get<double>() == Approx(lib.gamma_combined_k_m3_kg));
    CHECK(j.at("gamma_u_combined_k_m3_kg").get<double>() == Approx(lib.gamma_u_combined_k_m3_kg));
    CHECK(j.at("eq8").at("rmse_pct").get<double>() == Approx(lib.eq8.rmse_pct));
    // The text table is printed without --json.
    const auto text = run_manikin("physics cfd-gamma");
    REQUIRE(text.exit_code == 0);
    CHECK(text.out.find("Combined gamma") != std::string::npos);
}
