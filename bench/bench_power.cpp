// `manikin reconcile --power` against its floor (issue 62, part 2): the planner on the demo's
// campaign as a user runs it (a child process) on all cores, as it runs by default (a drawn lab's
// verdict its own verdicts at other values bracket is implied) and with `--power-every-lab` (each
// reconciled), both answers printed side by side with the labs that broke the order the default
// assumes; and the floor measured in the same run: the drawn campaigns the default plan
// reconciled, each reconciled once with the claim threshold given and its lab's grids shared
// (nothing of the planner around it), spread perfectly on the same threads. The goal: the demo's
// campaign and its seven terms in at most 180 s on two cores.
//
// Usage: bench_power [campaign folder]   (default: `manikin demo` into a temporary folder)
//   BENCH_POWER_TERMS=a,b       plan only these (--power-terms; default: every candidate)
//   BENCH_POWER_CAMPAIGNS=n     --power-campaigns (default 40)
//   BENCH_POWER_EVERY_LAB=0     skip the every-lab run (it is the long one)
//   BENCH_POWER_ONE_THREAD=1    also run on one thread (the answer must be the same)
//   BENCH_FLOOR_DRAWS=n         drawn campaigns timed for the floor (default 12)
#include <algorithm>
#include <chrono>
#include <cstdio>
#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <string>
#include <thread>
#include <vector>

#include <nlohmann/json.hpp>

#include "analysis/analyze.hpp"
#include "analysis/reconcile/evidence.hpp"
#include "analysis/reconcile/from_analysis.hpp"
#include "analysis/reconcile/reconcile.hpp"
#include "analysis/reconcile/twin_store.hpp"
#include "base/heap.hpp"
#include "base/lazy_library.hpp"
#include "bench/child_run.hpp"
#include "cli/campaign_source.hpp"

namespace fs = std::filesystem;
namespace rc = manikind::analysis::reconcile;
namespace ev = manikind::analysis::reconcile::evidence;
using manikind::bench::ChildRun;

namespace {

struct Plan {
    ChildRun run;
    nlohmann::json doc;
};

Plan plan(const std::string& manikin, const std::string& campaign, const fs::path& out, int threads, bool every_lab = false) {
    std::vector<std::string> args{"reconcile", campaign, "--power", "--json", "--threads", std::to_string(threads)};
    if (every_lab) args.push_back("--power-every-lab");
    if (const char* t = std::getenv("BENCH_POWER_TERMS")) args.insert(args.end(), {"--power-terms", t});
    if (const char* c = std::getenv("BENCH_POWER_CAMPAIGNS")) args.insert(args.end(), {"--power-campaigns", c});
    Plan p;
    p.run = manikind::bench::run_program(manikin, args, true, out.string());
    std::ifstream in(out);
    if (p.run.status == 0) p.doc = nlohmann::json::parse(in);
    return p;
}

void print_limits(const char* name, const nlohmann::json& doc) {
    std::printf("  %s:\n", name);
    for (const auto& l : doc["limits"]) {
        if (l["method"] != "whole decision") continue;
        std::printf("    %-28s %s", l["term"].get<std::string>().c_str(),
                    l["smallest_effect"].is_null() ? "not reached" : std::to_string(l["smallest_effect"].get<double>()).c_str());
        for (const auto& t : l["tried"])
            std::printf("  [%.4g: %d/%d, %d reconciled]", t["value"].get<double>(), t["named"].get<int>(), t["campaigns"].get<int>(),
                        t.value("reconciled", t["campaigns"].get<int>()));
        if (l.contains("non_monotone_labs") && !l["non_monotone_labs"].is_null())
            std::printf("  (%d labs named it at a value and missed it at a larger one)", l["non_monotone_labs"].get<int>());
        std::printf("\n");
    }
}

// The plan's whole-decision work alone: `draws` drawn campaigns reconciled one after another with
// the threshold given and each lab's grids made once (as the planner shares them across values).
double seconds_per_reconcile(const std::string& campaign, int draws) {
    manikind::cli::CampaignSource src;
    src.campaign = campaign;
    const auto c = manikind::cli::read_campaign_source(src);
    const auto result = manikind::analysis::analyze_campaign(c);
    const auto model = rc::make_twin_model(rc::case_inputs_from_results(result, c.zone_map),
                                           manikind::twin_store::load_twin_version("baseline"));
    rc::Options opt;
    opt.instruments = c.instruments;
    opt.null_threshold = rc::detection_limits(*model, opt, {3}, [] {
                             rc::PowerOptions po;
                             po.campaigns = 0;
                             po.terms = {"humidity_buoyancy"};
                             return po;
                         }()).claim_threshold.begin()->second;
    const auto simulator = model->campaign_simulator(opt.instruments, 1.0);
    const auto library = ev::single_library(*model);
    // A concealed effect near its limit, so that the decision goes as deep as the planner's does.
    const rc::CandidateTerm& term = library.front();
    const auto& p = term.parameters[0];
    const auto truth = rc::to_twin_terms(std::vector<rc::CandidateTerm>{term}, {p.null_value + 0.3 * (p.hi - p.null_value)});
    double total = 0.0;
    for (int i = 0; i < draws; ++i) {
        const auto sim = simulator->draw(truth, 3, opt.seed + 7919u * static_cast<std::uint64_t>(i + 1));
        const auto t0 = std::chrono::steady_clock::now();
        rc::Options o = opt;
        // Grids shared over about 25 uses in the demo's plan: their cost is counted once per lab.
        o.grids = std::make_shared<const std::vector<ev::Grid>>(ev::make_grids(*sim, ev::single_library(*sim), opt.grid_steps));
        const double grids_s = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
        const auto t1 = std::chrono::steady_clock::now();
        (void)rc::reconcile(*sim, o);
        total += std::chrono::duration<double>(std::chrono::steady_clock::now() - t1).count() + grids_s / 25.0;
    }
    return total / std::max(1, draws);
}

}  // namespace

int main(int argc, char** argv) {
    manikind::keep_freed_memory_for_reuse();  // as `manikin` does (its floor runs in this process)
    const std::string manikin = manikind::LazyLibrary::program_directory() + "/manikin";
    const fs::path dir = fs::temp_directory_path() / ("bench_power-" + std::to_string(::getpid()));
    fs::create_directories(dir);
    std::string campaign = argc > 1 ? argv[1] : "";
    if (campaign.empty()) {
        const ChildRun demo = manikind::bench::run_program(manikin, {"demo", "--out", (dir / "demo").string()}, true);
        if (demo.status != 0) {
            std::fprintf(stderr, "bench_power: manikin demo exited %d\n", demo.status);
            return 1;
        }
        campaign = (dir / "demo" / "campaign").string();
    }
    const int cores = std::max(1, static_cast<int>(std::thread::hardware_concurrency()));
    auto env_is = [](const char* name, const char* value) {
        const char* v = std::getenv(name);
        return v && std::string(v) == value;
    };
    const bool every_lab = !env_is("BENCH_POWER_EVERY_LAB", "0");
    const bool one_thread = env_is("BENCH_POWER_ONE_THREAD", "1");
    const Plan all = plan(manikin, campaign, dir / "all.json", cores);
    Plan every, one;
    if (every_lab) every = plan(manikin, campaign, dir / "every.json", cores, true);
    if (one_thread) one = plan(manikin, campaign, dir / "one.json", 1);
    if (all.run.status != 0 || (every_lab && every.run.status != 0) || (one_thread && one.run.status != 0)) {
        std::fprintf(stderr, "bench_power: manikin reconcile --power failed\n");
        return 1;
    }
    // The floor: the drawn campaigns the default plan reconciled, each once, on `cores` threads.
    int reconciled = 0;
    for (const auto& l : all.doc["limits"])
        for (const auto& t : l["tried"]) reconciled += t.value("reconciled", t["campaigns"].get<int>());
    const int draws = std::getenv("BENCH_FLOOR_DRAWS") ? std::max(1, std::atoi(std::getenv("BENCH_FLOOR_DRAWS"))) : 12;
    const double per = seconds_per_reconcile(campaign, draws);
    const double floor_s = per * reconciled / cores;

    std::printf("manikin reconcile --power on %s (%d cores)\n", campaign.c_str(), cores);
    std::printf("  default                %8.1f s wall %8.1f s CPU  (goal: at most 180 s for the demo's seven terms)\n",
                all.run.wall_s, all.run.cpu_s);
    if (every_lab) std::printf("  --power-every-lab      %8.1f s wall %8.1f s CPU\n", every.run.wall_s, every.run.cpu_s);
    if (one_thread) std::printf("  --threads 1            %8.1f s wall %8.1f s CPU\n", one.run.wall_s, one.run.cpu_s);
    std::printf("  floor                  %8.1f s wall  (%d drawn campaigns x %.3f s per reconcile / %d cores)\n", floor_s,
                reconciled, per, cores);
    std::printf("  planner / floor        %8.2fx\n", all.run.wall_s / std::max(1e-9, floor_s));
    print_limits("default", all.doc);
    if (every_lab) print_limits("--power-every-lab", every.doc);
    if (one_thread) {
        print_limits("--threads 1", one.doc);
        std::printf("  the same on one thread and on %d: %s\n", cores, one.doc["limits"] == all.doc["limits"] ? "yes" : "NO");
    }
    fs::remove_all(dir);
    return one_thread && one.doc["limits"] != all.doc["limits"] ? 1 : 0;
}
