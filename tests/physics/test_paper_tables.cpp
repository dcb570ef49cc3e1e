#include <catch2/catch.hpp>

#include "physics/paper_cfd_table.hpp"
#include "tests/physics/paper_csv.hpp"

using namespace manikind::physics;

TEST_CASE("Tables S8-S10: the embedded CFD table equals tests/data/paper/cfd_whole_body_cases.csv", "[physics][data]") {
    const auto rows = manikind::test::read_paper_csv("cfd_whole_body_cases.csv");
    const auto cases = paper_cfd_cases();
    REQUIRE(rows.size() == cases.size());
    for (std::size_t i = 0; i < rows.size(); ++i) {
        const auto& r = rows[i];
        const auto& c = cases[i];
        INFO("row " << i);
        CHECK(c.case_id == std::stoi(r.at("case")));
        CHECK(c.air_temp_c == manikind::test::num(r, "t_air_c"));
        CHECK(c.air_rh_pct == manikind::test::num(r, "rh_air_pct"));
        CHECK(c.dt_skin_air_c == manikind::test::num(r, "dt_sk_air_c"));
        CHECK(c.h_sim_w_m2k == manikind::test::num(r, "h_sim_w_m2k"));
        CHECK(c.q_sim_w_m2 == manikind::test::num(r, "q_sim_w_m2"));
        CHECK(c.h_dt_only_w_m2k == manikind::test::num(r, "h_dt_only_w_m2k"));
        CHECK(c.q_dt_only_w_m2 == manikind::test::num(r, "q_dt_only_w_m2"));
        CHECK(c.air_temp_c + c.dt_skin_air_c == Approx(cfd_skin_temp_c));
    }
}
