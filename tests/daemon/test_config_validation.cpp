// config::validate, the one check `manikin config check` and manikind both run: every refusal
// names the config file, line and key, and the bounded reader refuses what is not a TOML file.
#include <catch2/catch.hpp>

#include <sys/stat.h>
#include <sys/wait.h>
#include <unistd.h>

#include <array>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <random>
#include <string>

#include "daemon/config.hpp"
#include "base/toml_input.hpp"
#include "base/user_error.hpp"

using namespace manikind;
namespace fs = std::filesystem;

namespace {

// A fresh folder per test case, removed at the end.
class TempDir {
public:
    TempDir() {
        static int serial = 0;
        path_ = fs::temp_directory_path() / ("manikind-config-" + std::to_string(::getpid()) + "-" + std::to_string(serial++));
        fs::create_directories(path_);
    }
    ~TempDir() {
        std::error_code ec;
        fs::remove_all(path_, ec);
    }
    // Writes `text` to `name`, mode 0640 (a file holding a token must not be world-readable).
    fs::path write(const std::string& name, const std::string& text, unsigned mode = 0640) const {
        const fs::path p = path_ / name;
        std::ofstream(p) << text;
        ::chmod(p.c_str(), mode);
        return p;
    }
    const fs::path& path() const { return path_; }

private:
    fs::path path_;
};

// As `manikin config token` makes one: 32 random bytes, 64 hex characters.
std::string random_hex_token() {
    std::random_device rd;
    std::string t;
    for (int i = 0; i < 64; ++i) t += "0123456789abcdef"[rd() % 16];
    return t;
}

std::string joined(const std::vector<std::string>& problems) {
    std::string s;
    for (const auto& p : problems) s += p + "\n";
    return s;
}

std::vector<std::string> problems_of(const fs::path& file) { return config::validate(config::load_config(file)); }

// A complete mode = "real" file; `safety` replaces the [safety] section.
std::string real_lab_toml(const std::string& token, const std::string& safety) {
    return "[lab]\nmode = \"real\"\ndatabase = \"lab.db\"\n"
           "[api]\nsocket = \"lab.sock\"\ntoken = \"" + token + "\"\n" + safety +
           "[devices.chamber]\nhost = \"10.0.0.2\"\n"
           "[devices.datalogger]\nserial = \"/dev/ttyUSB3\"\n"
           "[devices.windsonic]\npath = \"/dev/ttyUSB0\"\n"
           "[devices.csat3b]\npath = \"/dev/ttyUSB1\"\n"
           "[devices.manikin]\ninterface = \"can0\"\n";
}

const std::string all_safety_keys =
    "[safety]\nmax_skin_temp_c = 40.0\nmin_skin_temp_c = 25.0\nmax_heater_temp_c = 50.0\nmax_heater_power_w_m2 = 650.0\n"
    "min_chamber_temp_c = 10.0\nmax_chamber_temp_c = 50.0\nmin_chamber_rh_pct = 10.0\nmax_chamber_rh_pct = 90.0\n"
    "watchdog_timeout_s = 10.0\n";

}  // namespace

TEST_CASE("a register map file that does not exist is refused naming the config file, line and key", "[daemon][config]") {
    TempDir dir;
    const auto file = dir.write("lab.toml", "[devices.chamber]\nregister_map = \"missing_registers.toml\"\n");
    const auto p = joined(problems_of(file));
    CHECK_THAT(p, Catch::Contains(file.string() + ":2:") && Catch::Contains("devices.chamber.register_map: ") &&
                      Catch::Contains("missing_registers.toml: cannot open"));
}

TEST_CASE("/etc/passwd as a register map is refused with its TOML syntax error, naming the config line and key", "[daemon][config]") {
    TempDir dir;
    const auto file = dir.write("lab.toml", "[devices]\n[devices.datalogger]\nregister_map = \"/etc/passwd\"\n");
    const auto p = joined(problems_of(file));
    CHECK_THAT(p, Catch::Contains(file.string() + ":3:") && Catch::Contains("devices.datalogger.register_map: /etc/passwd:1:"));
}

TEST_CASE("a directory as a register map is refused as a directory, naming the config line and key", "[daemon][config]") {
    TempDir dir;
    const auto file = dir.write("lab.toml", "[devices.chamber]\nregister_map = \".\"\n");
    const auto p = joined(problems_of(file));
    CHECK_THAT(p, Catch::Contains(file.string() + ":2:") && Catch::Contains("devices.chamber.register_map: ") &&
                      Catch::Contains("is a directory, expected a TOML register map"));
}

TEST_CASE("/dev/zero as a register map is refused at once (stat first, never read to the end)", "[daemon][config]") {
    TempDir dir;
    const auto file = dir.write("lab.toml", "[devices.chamber]\nregister_map = \"/dev/zero\"\n");
    // "not a regular file" is the stat's verdict: a reader of the file would have had none to give
    // (and no wall-clock cap decides this: a loaded machine must not fail it).
    const auto p = joined(problems_of(file));
    CHECK_THAT(p, Catch::Contains(file.string() + ":2:") && Catch::Contains("devices.chamber.register_map: /dev/zero: ") &&
                      Catch::Contains("not a regular file"));
}

TEST_CASE("a FIFO, a directory and a file over 1 MiB are refused as configuration files without being read", "[daemon][config]") {
    TempDir dir;
    const auto fifo = dir.path() / "fifo.toml";
    REQUIRE(::mkfifo(fifo.c_str(), 0600) == 0);
    // A FIFO with no writer would block an open() forever; the stat refuses it first.
    CHECK_THROWS_WITH(config::load_config(fifo), Catch::Contains("is a FIFO, not a regular file"));
    CHECK_THROWS_WITH(config::load_config(dir.path()), Catch::Contains("is a directory, expected a TOML configuration file"));
    const auto big = dir.write("big.toml", "# " + std::string(toml_input::max_toml_bytes, 'x') + "\n");
    CHECK_THROWS_WITH(config::load_config(big), Catch::Contains("1.0 MiB (1048579 bytes) is over the 1 MiB limit for a TOML configuration file"));
    CHECK_THROWS_WITH(config::load_config(dir.path() / "absent.toml"), Catch::Contains("cannot open"));
}

TEST_CASE("malformed world-effect and fault entries are refused with file:line, the element and the parser's reason", "[daemon][config]") {
    TempDir dir;
    const auto file = dir.write("sim.toml",
                                "[simulation]\n"
                                "world_effects = [\"humidity_buoyancy:gamma=146\", \"no_such_term:x=1\"]\n"
                                "faults = [\"windsonic:silent@1200-1260\",\n"
                                "          \"toaster:on_fire\"]\n");
    const auto problems = problems_of(file);
    REQUIRE(problems.size() == 2);
    CHECK_THAT(problems[0], Catch::StartsWith(file.string() + ":2:") &&
                                Catch::Contains("simulation.world_effects[1]: 'no_such_term:x=1': --effect"));
    CHECK_THAT(problems[1], Catch::StartsWith(file.string() + ":4:") &&
                                Catch::Contains("simulation.faults[1]: 'toaster:on_fire': fault 'toaster:on_fire'"));
}

TEST_CASE("[[simulation.local]]: a non-uniform simulated room is read entry by entry, an unknown zone, a missing zone "
          "list or a value out of range is refused with file:line and key, and the shipped templates pass",
          "[daemon][config][local]") {
    TempDir dir;
    const auto good = dir.write("cabin.toml",
                                "[simulation]\n"
                                "[[simulation.local]]\n"
                                "what = \"vents\"\n"
                                "zones = [\"face\", \"hand\"]\n"
                                "air_offset_c = -3\n"
                                "air_speed_m_s = 0.6\n"
                                "[[simulation.local]]\n"
                                "zones = [\"head\"]\n"
                                "radiant_offset_c = 8\n"
                                "solar_w_m2 = 30\n"
                                "contact_w_m2 = -20\n");
    const auto c = config::load_config(good);
    REQUIRE(c.simulation.local.size() == 2);
    CHECK(c.simulation.local[0].zones == std::vector<std::string>{"face", "hand"});
    CHECK(c.simulation.local[0].air_speed_m_s == 0.6);
    CHECK(c.simulation.local[1].air_speed_m_s < 0.0);  // the room's
    CHECK(c.simulation.local[1].contact_w_m2 == -20.0);
    CHECK_THAT(c.simulation.local[1].where, Catch::StartsWith(good.string() + ":7"));
    CHECK(problems_of(good).empty());

    const auto unknown = dir.write("unknown.toml", "[[simulation.local]]\nzones = [\"face\"]\n[[simulation.local]]\n"
                                                   "zones = [\"tail\"]\nair_offset_c = 1\n");
    const auto problems = problems_of(unknown);
    REQUIRE(problems.size() == 1);
    CHECK_THAT(problems[0], Catch::StartsWith(unknown.string() + ":3") &&
                                Catch::Contains("simulation.local[1].zones: 'tail' is no zone, region or segment"));
    CHECK_THROWS_WITH(config::load_config(dir.write("range.toml", "[[simulation.local]]\nzones = [\"face\"]\nradiant_offset_c = 90\n")),
                      Catch::Contains("range.toml:3") && Catch::Contains("simulation.local[0].radiant_offset_c: 90 K is outside -60..60"));
    CHECK_THROWS_WITH(config::load_config(dir.write("nozones.toml", "[[simulation.local]]\nair_offset_c = 1\n")),
                      Catch::Contains("nozones.toml:1") && Catch::Contains("simulation.local[0].zones: expected the zones"));
    CHECK_THROWS_WITH(config::load_config(dir.write("table.toml", "[simulation]\nlocal = 3\n")),
                      Catch::Contains("table.toml:2") && Catch::Contains("expected [[simulation.local]] tables"));
    const auto typo = config::load_config(dir.write("typo.toml", "[[simulation.local]]\nzones = [\"face\"]\nsolar_wm2 = 3\n"));
    REQUIRE(typo.warnings.size() == 1);
    CHECK_THAT(typo.warnings[0], Catch::Contains("simulation.local[0].solar_wm2: unknown key"));
    for (const char* shipped : {"sim-car-cabin-summer.toml", "sim-office-displacement.toml"}) {
        INFO(shipped);
        const auto t = config::load_config(fs::path(MANIKIND_CONFIG_DIR) / shipped);
        CHECK(t.simulation.local.size() >= 4);
        CHECK(t.warnings.empty());
        CHECK(problems_of(fs::path(MANIKIND_CONFIG_DIR) / shipped).empty());
    }
}

TEST_CASE("a control socket path over 107 characters (with .token beside it) is refused with its length and the limit", "[daemon][config]") {
    TempDir dir;
    const std::string long_socket = "/tmp/" + std::string(110, 's') + ".sock";  // 120 characters
    const auto file = dir.write("lab.toml", "[api]\nsocket = \"" + long_socket + "\"\n");
    CHECK_THAT(joined(problems_of(file)), Catch::Contains(file.string() + ":2:") &&
                                              Catch::Contains("api.socket: '" + long_socket + "' is 120 characters") &&
                                              Catch::Contains("at most 107"));
    // 102 characters fit in sun_path, but "<socket>.token" (108) does not.
    const std::string edge = "/tmp/" + std::string(92, 'e') + ".sock";
    REQUIRE(edge.size() == 102);
    CHECK_THAT(joined(problems_of(dir.write("edge.toml", "[api]\nsocket = \"" + edge + "\"\n"))),
               Catch::Contains("is 102 characters, 108 with '.token'"));
    const std::string fits = "/tmp/" + std::string(91, 'f') + ".sock";  // 101 + 6 = 107
    CHECK(problems_of(dir.write("fits.toml", "[api]\nsocket = \"" + fits + "\"\n")).empty());
}

TEST_CASE("mode real without [safety], or with one safety key missing, is refused listing the missing keys", "[daemon][config]") {
    TempDir dir;
    const std::string token = random_hex_token();
    CHECK(problems_of(dir.write("complete.toml", real_lab_toml(token, all_safety_keys))).empty());

    const auto none = dir.write("no-safety.toml", real_lab_toml(token, ""));
    const auto p = joined(problems_of(none));
    CHECK_THAT(p, Catch::Contains(none.string() + ":2:") &&
                      Catch::Contains("missing: max_skin_temp_c, min_skin_temp_c, max_heater_temp_c, max_heater_power_w_m2, "
                                      "min_chamber_temp_c, max_chamber_temp_c, min_chamber_rh_pct, max_chamber_rh_pct, "
                                      "watchdog_timeout_s"));

    std::string without_watchdog = all_safety_keys;
    without_watchdog.erase(without_watchdog.find("watchdog_timeout_s"));
    const auto problems = problems_of(dir.write("one-missing.toml", real_lab_toml(token, without_watchdog)));
    REQUIRE(problems.size() == 1);
    CHECK_THAT(problems[0], Catch::EndsWith("missing: watchdog_timeout_s"));

    // No silent fallback to the simulated lab's addresses either.
    const auto bare = joined(problems_of(dir.write("bare.toml", "[lab]\nmode = \"real\"\n" + all_safety_keys)));
    for (const char* key : {"lab.database", "devices.chamber: ", "devices.datalogger: ", "devices.windsonic.path",
                            "devices.csat3b.path", "devices.manikin.interface", "api.token"})
        CHECK_THAT(bare, Catch::Contains(key));
}

TEST_CASE("placeholder, short and low-entropy API tokens are refused, a manikin-config-token-style random one is accepted", "[daemon][config]") {
    CHECK_THAT(config::token_problem("change-me-to-a-long-random-string"), Catch::Contains("placeholder"));
    CHECK_THAT(config::token_problem("MySecretTokenForTheLab1234567"), Catch::Contains("placeholder"));
    CHECK_THAT(config::token_problem("Xk3-9fQ"), Catch::Contains("7 characters, fewer than 24"));
    CHECK_THAT(config::token_problem("abababababababababababababab"), Catch::Contains("only 2 distinct characters"));
    // 11 distinct characters, but 40 of 50 are the same: about 69 bits.
    CHECK_THAT(config::token_problem(std::string(40, 'a') + "0123456789"), Catch::Contains("about 69 bits"));
    CHECK_THAT(config::token_problem("Xk3-9fQ"), Catch::Contains("manikin config token") && Catch::Contains("openssl rand -hex 32"));
    CHECK(config::token_problem(random_hex_token()).empty());

    TempDir dir;
    const auto file = dir.write("lab.toml", "[api]\nsocket = \"lab.sock\"\ntoken = \"short\"\n");
    CHECK_THAT(joined(problems_of(file)), Catch::Contains(file.string() + ":3:") && Catch::Contains("api.token: is 5 characters"));
}

TEST_CASE("a config file readable by every user (0644) that holds the API token is refused, 0640 is accepted", "[daemon][config]") {
    TempDir dir;
    const std::string text = "[api]\ntoken = \"" + random_hex_token() + "\"\n";
    const auto open_file = dir.write("open.toml", text, 0644);
    const auto problems = problems_of(open_file);
    REQUIRE(problems.size() == 1);
    CHECK(problems[0] == open_file.string() + ": holds the API token but is readable by every user (mode 0644): chmod 640 " +
                             open_file.string());
    CHECK(problems_of(dir.write("closed.toml", text, 0640)).empty());
    CHECK(problems_of(dir.write("no-token.toml", "[api]\ntoken = \"\"\n", 0644)).empty());  // nothing to leak
}

TEST_CASE("the built-in simulated config passes validation", "[daemon][config]") {
    CHECK(config::validate(config::default_config()).empty());
    CHECK_NOTHROW(config::require_valid(config::default_config()));
    CHECK(config::default_config().api.max_clients == 64);
    CHECK(config::default_config().api.idle_timeout_s == 120);
}

TEST_CASE("the [api] max_clients and idle_timeout_s keys are read and range-checked", "[daemon][config]") {
    const auto c = config::parse_config("[api]\nmax_clients = 8\nidle_timeout_s = 30\n", "lab.toml");
    CHECK(c.api.max_clients == 8);
    CHECK(c.api.idle_timeout_s == 30);
    CHECK(c.warnings.empty());
    CHECK_THROWS_WITH(config::parse_config("[api]\nmax_clients = 0\n", "lab.toml"), Catch::Contains("lab.toml:2") && Catch::Contains("api.max_clients"));
    CHECK_THROWS_WITH(config::parse_config("[api]\nidle_timeout_s = 90000\n", "lab.toml"), Catch::Contains("api.idle_timeout_s"));
    CHECK(c.key_where.at("api.max_clients") == "lab.toml:2:15");
}

TEST_CASE("the [api] partial_grace_s and max_clients_per_peer keys are read and range-checked", "[daemon][config]") {
    const auto c = config::parse_config("[api]\npartial_grace_s = 0.2\nmax_clients_per_peer = 8\n", "lab.toml");
    CHECK(c.api.partial_grace_s == 0.2);
    CHECK(c.api.max_clients_per_peer == 8);
    CHECK(config::default_config().api.partial_grace_s == 0.5);
    CHECK(config::default_config().api.max_clients_per_peer == 0);
    CHECK_THROWS_WITH(config::parse_config("[api]\npartial_grace_s = 0\n", "lab.toml"), Catch::Contains("api.partial_grace_s"));
    CHECK_THROWS_WITH(config::parse_config("[api]\nmax_clients_per_peer = 5000\n", "lab.toml"),
                      Catch::Contains("api.max_clients_per_peer"));
}

TEST_CASE("manikind refuses to start on a file config check refuses, with the same file:line: key message", "[daemon][config]") {
    TempDir dir;
    const auto file = dir.write("lab.toml", "[simulation]\nfaults = [\"toaster:on_fire\"]\n");
    const std::string command = std::string(MANIKIND_BIN_DIR) + "/manikind --virtual --config " + file.string() +
                                " --socket " + (dir.path() / "d.sock").string() + " --database " +
                                (dir.path() / "d.db").string() + " 2>&1";
    FILE* pipe = ::popen(command.c_str(), "r");
    REQUIRE(pipe);
    std::string out;
    std::array<char, 4096> buf{};
    std::size_t n = 0;
    while ((n = std::fread(buf.data(), 1, buf.size(), pipe)) > 0) out.append(buf.data(), n);
    const int status = ::pclose(pipe);
    CHECK(WEXITSTATUS(status) == 2);
    CHECK_THAT(out, Catch::Contains(file.string() + ":2:") && Catch::Contains("simulation.faults[0]: 'toaster:on_fire'"));
    CHECK_FALSE(fs::exists(dir.path() / "d.sock"));
}

TEST_CASE("[notifications]: unknown events, URLs of other schemes, e-mail without sender or with a smuggled header are refused with the line",
          "[daemon][config][notify]") {
    const auto c = config::parse_config(R"([notifications]
events = ["safety", "gossip"]
webhook_url = "file:///etc/passwd"
smtp_url = "smtp://127.0.0.1:25"
mail_to = ["ana@lab.example", "bo@lab.example\r\nBcc: all@x"]
)", "lab.toml");
    const std::string all = joined(config::validate(c));
    CHECK_THAT(all, Catch::Contains("lab.toml:2") && Catch::Contains("notifications.events: 'gossip' is not one of"));
    CHECK_THAT(all, Catch::Contains("lab.toml:3") && Catch::Contains("notifications.webhook_url: expected http://... or https://..."));
    CHECK_THAT(all, Catch::Contains("notifications: an smtp_url needs mail_from"));
    CHECK_THAT(all, Catch::Contains("notifications.mail_to: expected a plain address"));
    // A good one passes.
    const auto good = config::parse_config(R"([notifications]
events = ["safety", "alarm_error", "campaign_end", "steady"]
webhook_url = "https://ntfy.sh/lab"
webhook_format = "slack"
smtp_url = "smtps://mail.lab.example:465"
mail_from = "manikind@lab.example"
mail_to = ["ana@lab.example"]
)", "lab.toml");
    CHECK(joined(config::validate(good)).find("notifications") == std::string::npos);
    CHECK_THROWS_WITH(config::parse_config("[notifications]\nwebhook_format = \"xml\"\n", "lab.toml"),
                      Catch::Contains("notifications.webhook_format: 'xml' is not one of json, matrix, slack"));
}
