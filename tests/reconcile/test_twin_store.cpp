#include <catch2/catch.hpp>

#include "analysis/reconcile/twin_store.hpp"
#include "base/user_error.hpp"

using namespace manikind;

TEST_CASE("twin store: a version round-trips through TOML with its terms and values", "[twin_store]") {
    physics::twin::TwinVersion v{"reconciled", {{"humidity_buoyancy", {{"gamma", 151.25}}, "", {}},
                                                {"partial_wettedness", {{"fraction", 0.3}}, "head", {}},
                                                {"heat_leak", {{"q_w_m2", 12.5}}, "", {5, 23}},
                                                {"input_pattern", {{"value", 1.25}}, "", {}, "air_temp_c", "height"}}};
    const auto back = twin_store::parse_twin_version(twin_store::twin_version_to_toml(v, "baseline", "test"), "v.toml");
    CHECK(back.name == "reconciled");
    REQUIRE(back.terms.size() == 4);
    CHECK(back.terms[3].input == "air_temp_c");
    CHECK(back.terms[3].pattern == "height");
    CHECK(back.terms[3].parameters.at("value") == 1.25);
    CHECK(back.terms[0].parameters.at("gamma") == 151.25);
    CHECK(back.terms[1].region == "head");
    CHECK(back.terms[2].zones == std::vector<int>{5, 23});
    CHECK(twin_store::load_twin_version("baseline").terms.empty());
}

TEST_CASE("twin store: unknown terms and bad values name the file and line", "[twin_store]") {
    CHECK_THROWS_WITH(twin_store::parse_twin_version("name = \"x\"\n[[terms]]\nname = \"warp\"\n", "v.toml"),
                      Catch::Contains("v.toml:2:") && Catch::Contains("warp"));
    CHECK_THROWS_WITH(twin_store::parse_twin_version("[[terms]]\nname = \"humidity_buoyancy\"\ngamma = \"lots\"\n", "v.toml"),
                      Catch::Contains("v.toml:3:") && Catch::Contains("expected a number"));
    CHECK_THROWS_AS(twin_store::load_twin_version("/nonexistent.toml"), UserError);
    // A generated hypothesis names an input and a pattern the twin knows.
    CHECK_THROWS_WITH(twin_store::parse_twin_version("[[terms]]\nname = \"input_pattern\"\ninput = \"air_speed\"\n"
                                                     "pattern = \"height\"\nvalue = 1\n", "v.toml"),
                      Catch::Contains("v.toml:1:") && Catch::Contains("unknown input 'air_speed'"));
}
