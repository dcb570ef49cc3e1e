// Issue 19's proof across labs: two simulated labs (different seeds; lab B's air is 2 °C cooler
// than its probe says, a bias nothing in the analysis is told about) run the same campaign and
// write one PostgreSQL archive: lab A through the daemon's own forwarding, lab B offline with
// `manikin archive push`. From the archive alone, `manikin archive compare` shows the
// between-lab spread (ISO 5725-2) and `manikin reconcile --archive` per lab names the bias in
// lab B only.
#include <sys/wait.h>
#include <unistd.h>

#include <cmath>
#include <cstdint>
#include <filesystem>
#include <fstream>
#include <future>
#include <string>

#include <catch2/catch.hpp>
#include <nlohmann/json.hpp>

#include "tests/archive/archive_checks.hpp"
#include "tests/archive/pg_server.hpp"
#include "tests/daemon/daemon_process.hpp"

namespace {

namespace fs = std::filesystem;
using manikind::test::DaemonProcess;
using manikind::test::PgServer;
using manikind::test::run_manikin;

// Dry cases 1 and 4 and wet cases 5 and 13 of Table S3, three replicates: enough for reconcile to
// tell an air-temperature bias from the other candidates, small enough for a test. Three
// replicates: a trial that never settles (the simulated manikin sometimes oscillates) still
// leaves two.
constexpr const char* plan_toml = R"(name = "round-robin"
replicates = 3
trial_duration_min = 35
[[cases]]
id = 1
chamber_temp_c = 40
chamber_rh_pct = 24.6
skin_setpoint_c = 34
wet = false
[[cases]]
id = 4
chamber_temp_c = 44
chamber_rh_pct = 20
skin_setpoint_c = 31
wet = false
[[cases]]
id = 5
chamber_temp_c = 35
chamber_rh_pct = 27
skin_setpoint_c = 35
wet = true
[[cases]]
id = 13
chamber_temp_c = 44
chamber_rh_pct = 22
skin_setpoint_c = 35
wet = true
)";

DaemonProcess run_lab(const fs::path& dir, const std::string& lab) {
    return DaemonProcess::spawn({std::string(MANIKIND_BIN_DIR) + "/manikind", "--virtual", "--config",
                                 (dir / (lab + ".toml")).string(), "--database", (dir / (lab + ".db")).string(),
                                 "--socket", (dir / (lab + ".sock")).string(), "--campaign",
                                 (dir / "plan.toml").string(), "--exit-when-done"});
}

const nlohmann::json& case_of(const nlohmann::json& report, int id) {
    for (const auto& c : report["cases"])
        if (c["case"] == id) return c;
    throw std::runtime_error("no case " + std::to_string(id) + " in the report");
}

double lab_q(const nlohmann::json& c, const std::string& lab) {
    for (const auto& l : c["labs"])
        if (l["lab"] == lab) return l["q_w_m2"].get<double>();
    throw std::runtime_error("no lab " + lab);
}

}  // namespace

TEST_CASE("two labs, one archive: the cross-lab report shows the between-lab spread and reconcile finds lab B's "
          "concealed probe bias in lab B only",
          "[archive][interlab]") {
    PgServer pg;
    const fs::path dir = fs::temp_directory_path() / ("manikind-round-robin-" + std::to_string(::getpid()));
    fs::remove_all(dir);
    fs::create_directories(dir);
    {
        std::ofstream(dir / "plan.toml") << plan_toml;
        // Both log every 5 s, as the paper did (Text S3.2) and `manikin demo` does: a fifth of the
        // virtual clock's steps of the 1-s default, for the same trials.
        const char* five_s = "[devices]\npoll_period_s = 5.0\n";
        std::ofstream(dir / "lab-a.toml") << five_s << "[lab]\nchamber = \"chamber A\"\n[simulation]\nstep_s = 5.0\nseed = 11\nworld_effects = []\n"
                                          << "[archive]\npostgresql = \"" << pg.conninfo()
                                          << "\"\nlab_id = \"lab-a\"\ninterval_s = 1\n";
        std::ofstream(dir / "lab-b.toml") << five_s << "[lab]\nchamber = \"chamber B\"\n[simulation]\nstep_s = 5.0\nseed = 12\n"
                                          << "world_effects = [\"air_temp_bias:bias_c=2.0\"]\n";
    }
    // The two chambers run at the same time, as two labs do.
    auto lab_a = run_lab(dir, "lab-a");
    auto lab_b = run_lab(dir, "lab-b");
    const int status_a = lab_a.wait(), status_b = lab_b.wait();
    INFO(lab_a.output() << lab_b.output());
    REQUIRE(WIFEXITED(status_a));
    REQUIRE(WEXITSTATUS(status_a) == 0);
    REQUIRE(WIFEXITED(status_b));
    REQUIRE(WEXITSTATUS(status_b) == 0);

    // Lab B is offline: its file is pushed. Lab A forwarded as it ran; a push finishes whatever
    // the daemon's last 10-s pass at exit left, and adds nothing twice.
    const std::string archive = "'" + pg.conninfo() + "'";
    auto push_b = std::async(std::launch::async, [&] {
        return run_manikin("archive push " + (dir / "lab-b.db").string() + " --to " + archive + " --lab lab-b --json");
    });
    const auto pushed_a =
        run_manikin("archive push " + (dir / "lab-a.db").string() + " --to " + archive + " --lab lab-a --json");
    REQUIRE(pushed_a.status == 0);
    REQUIRE(push_b.get().status == 0);
    std::int64_t lab_a_rows = 0;
    for (const auto& [uuid, sums] : manikind::test::sqlite_sums(dir / "lab-a.db")) lab_a_rows += sums.rows;
    CHECK(nlohmann::json::parse(pushed_a.out)["samples"]["added"].get<std::int64_t>() < lab_a_rows);  // the daemon sent some
    manikind::test::check_archive_equals_sqlite(dir / "lab-a.db", pg.conninfo(), "lab-a");
    manikind::test::check_archive_equals_sqlite(dir / "lab-b.db", pg.conninfo(), "lab-b");

    // The cross-lab report, from the archive alone.
    const auto compared = run_manikin("archive compare --archive " + archive + " --campaign round-robin --json");
    REQUIRE(compared.status == 0);
    const auto report = nlohmann::json::parse(compared.out);
    CHECK(report["labs"] == nlohmann::json::array({"lab-a", "lab-b"}));
    // Each lab's set-up: one per lab (each daemon ran once), naming its own chamber.
    REQUIRE(report["setups"]["lab-a"].size() == 1);
    REQUIRE(report["setups"]["lab-b"].size() == 1);
    CHECK(report["setups"]["lab-a"][0]["chamber"] == "chamber A");
    CHECK(report["setups"]["lab-b"][0]["chamber"] == "chamber B");
    CHECK(report["setups"]["lab-b"][0]["trials"] == 12);
    CHECK(report["setups"]["lab-a"][0]["setup_sha256"] != report["setups"]["lab-b"][0]["setup_sha256"]);
    REQUIRE(report["cases"].size() == 4);
    // A trial that never settles is left out by the analysis (the simulated manikin sometimes
    // oscillates); a case keeps its estimate while each lab has two usable replicates of it.
    int with_precision = 0;
    for (const auto& c : report["cases"]) {
        INFO("case " << c["case"]);
        if (!c["precision"].is_object()) {
            CHECK_THAT(c["note"].get<std::string>(), Catch::Contains("ISO 5725-2 needs two"));
            continue;
        }
        ++with_precision;
        const auto& p = c["precision"];
        CHECK(p["labs"] == 2);
        // ISO 5725-2: s_R² = s_r² + s_L², R = 2.8 s_R.
        CHECK(p["reproducibility_sd_w_m2"].get<double>() ==
              Approx(std::hypot(p["repeatability_sd_w_m2"].get<double>(), p["between_lab_sd_w_m2"].get<double>())));
        CHECK(p["reproducibility_limit_w_m2"].get<double>() ==
              Approx(2.8 * p["reproducibility_sd_w_m2"].get<double>()));
    }
    CHECK(with_precision >= 3);
    // Physics: lab B's true air is 2 °C cooler than recorded, so its manikin loses more heat in
    // every case (more convective loss, and in the wet cases more evaporation). In case 4 (44 °C
    // air, 31 °C skin: the largest gradient, the steadiest flux, replicates within ~1 W/m²) the
    // labs differ by far more than the replicates within a lab do.
    for (const int id : {1, 4, 5, 13}) {
        INFO("case " << id);
        CHECK(lab_q(case_of(report, id), "lab-b") > lab_q(case_of(report, id), "lab-a"));
    }
    const auto& case4 = case_of(report, 4);
    REQUIRE(case4["precision"].is_object());
    CHECK(case4["precision"]["between_lab_sd_w_m2"].get<double>() > 2.0 * case4["precision"]["repeatability_sd_w_m2"].get<double>());

    // Reconcile per lab, from the archive: the bias is named in lab B, with an interval that holds
    // the 2.0 °C put in; lab A has nothing to explain.
    const auto rec_a = run_manikin("reconcile --archive " + archive + " --lab lab-a --campaign round-robin --json");
    const auto rec_b = run_manikin("reconcile --archive " + archive + " --lab lab-b --campaign round-robin --json");
    INFO(rec_a.out.substr(0, 600) << rec_b.out.substr(0, 600));
    REQUIRE(rec_a.status == 0);
    REQUIRE(rec_b.status == 0);
    const auto ja = nlohmann::json::parse(rec_a.out), jb = nlohmann::json::parse(rec_b.out);
    CHECK((ja["explanation"].is_null() || ja["explanation"]["term"] != "air_temp_bias"));
    REQUIRE(jb["explanation"].is_object());
    CHECK(jb["explanation"]["term"] == "air_temp_bias");
    const auto interval = jb["explanation"]["interval_95"]["bias_c"];
    CHECK(interval[0].get<double>() < 2.0);
    CHECK(interval[1].get<double>() > 2.0);
    fs::remove_all(dir);
}
