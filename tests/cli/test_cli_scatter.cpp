// `manikin simulate-campaign` replicate-scatter options, run as a user would.
#include <catch2/catch.hpp>

#include <cmath>
#include <filesystem>
#include <fstream>
#include <numeric>

#include "analysis/recording.hpp"
#include "tests/cli/run_cli.hpp"

using manikind::test::run_manikin;

namespace {

std::filesystem::path scatter_dir(const std::string& name) {
    const auto dir = std::filesystem::temp_directory_path() / ("manikind-test-" + name);
    std::filesystem::remove_all(dir);
    std::filesystem::create_directories(dir);
    return dir;
}

// Pooled between-replicate sd of each zone's mean flux over the last 30 min, W/m².
double pooled_replicate_sd_w_m2(const manikind::analysis::Campaign& c) {
    const std::size_t n_zones = c.trials.front().data.heat_flux_w_m2.size();
    double var_sum = 0.0;
    for (std::size_t z = 0; z < n_zones; ++z) {
        std::vector<double> steady;
        for (const auto& t : c.trials) {
            const auto& q = t.data.heat_flux_w_m2[z];
            double sum = 0.0;
            std::size_t n = 0;
            for (std::size_t k = 0; k < q.size(); ++k)
                if (t.data.t_s[k] >= t.data.t_s.back() - 1800.0) {
                    sum += q[k];
                    ++n;
                }
            steady.push_back(sum / static_cast<double>(n));
        }
        const double m = std::accumulate(steady.begin(), steady.end(), 0.0) / static_cast<double>(steady.size());
        double ss = 0.0;
        for (double x : steady) ss += (x - m) * (x - m);
        var_sum += ss / static_cast<double>(steady.size() - 1);
    }
    return std::sqrt(var_sum / static_cast<double>(n_zones));
}

}  // namespace

TEST_CASE("cli: simulate-campaign --help names every scatter option with its default", "[cli][scatter]") {
    const auto r = run_manikin("simulate-campaign --help");
    REQUIRE(r.exit_code == 0);
    for (const char* option : {"--replicate-flux-rel-sd", "--replicate-flux-sd", "--replicate-air-sd", "--replicate-rh-sd",
                               "--replicate-wall-sd", "--probe-air-sd", "--probe-rh-sd", "--probe-wall-sd", "--no-scatter"})
        CHECK_THAT(r.out, Catch::Contains(option));
    CHECK_THAT(r.out, Catch::Contains("0.015"));
    CHECK_THAT(r.out, Catch::Contains("constant within a trial"));
    // --no-scatter with a spread given is a contradiction, refused.
    CHECK(run_manikin("simulate-campaign --no-scatter --probe-air-sd 0.1 --out /tmp/manikind-never 2>&1").exit_code != 0);
    CHECK(run_manikin("simulate-campaign --probe-rh-sd -1 --out /tmp/manikind-never 2>&1").exit_code == 2);
}

TEST_CASE("cli: --no-scatter writes replicates identical up to sensor noise, the default scatters them", "[cli][scatter]") {
    const auto dir = scatter_dir("scatter");
    {
        std::ofstream cases(dir / "cases.csv");
        cases << "case,t_chamber_set_c,rh_chamber_set_pct,t_air_c,rh_air_pct,t_skin_c,skin_wettedness\n"
                 "9,40,19,39.6,38.3,35.0,1\n";
    }
    const std::string common = "simulate-campaign --seed 4 --replicates 5 --cases " + (dir / "cases.csv").string();
    REQUIRE(run_manikin(common + " --no-scatter --out " + (dir / "exact").string()).exit_code == 0);
    REQUIRE(run_manikin(common + " --out " + (dir / "scattered").string()).exit_code == 0);
    const auto exact = manikind::analysis::read_campaign(dir / "exact");
    const auto scattered = manikind::analysis::read_campaign(dir / "scattered");
    REQUIRE(exact.trials.size() == 5);
    REQUIRE(scattered.trials.size() == 5);

    // 1.5 W/m² sensor noise over 361 samples: 30-min means scatter by 0.079 W/m² between replicates.
    const double noise_of_mean_w_m2 = 1.5 / std::sqrt(361.0);
    const double exact_sd = pooled_replicate_sd_w_m2(exact);
    CHECK(exact_sd == Approx(noise_of_mean_w_m2).epsilon(0.5));
    CHECK(pooled_replicate_sd_w_m2(scattered) > 10.0 * noise_of_mean_w_m2);
    // The recorded air temperature: the case's nominal, to within the noise of a 901-sample mean.
    for (const auto& t : exact.trials) {
        const auto& a = t.data.air_temp_c;
        CHECK(std::accumulate(a.begin(), a.end(), 0.0) / static_cast<double>(a.size()) == Approx(39.6).margin(0.006));
    }
    std::filesystem::remove_all(dir);
}
