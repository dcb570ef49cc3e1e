// `manikin calibrate <campaign>` and `manikin teq <campaign> --calibration FILE`: the manikin's
// heat-transfer coefficients from a uniform calibration environment, and the equivalent
// temperature (ISO 14505-2) per zone, region and whole body with 95 % intervals and a
// comfort-zone diagram (analysis/teq.hpp, docs/comfort.md).
#include <chrono>
#include <cstdio>
#include <fstream>
#include <memory>
#include <optional>
#include <stdexcept>
#include <string>

#include <fmt/core.h>
#include <spdlog/spdlog.h>

#include "analysis/input_error.hpp"
#include "analysis/teq.hpp"
#include "base/user_error.hpp"
#include "cli/campaign_source.hpp"
#include "cli/commands.hpp"
#include "store/export_target.hpp"
#include "store/hdf5_export.hpp"

namespace manikind::cli {
namespace {

// Writes `text` to a checked target whole, then renames it into place.
void write_target(ExportTarget& target, const std::string& text, const std::string& what) {
    {
        std::ofstream out(target.staging(), std::ios::binary | std::ios::trunc);
        out << text;
        out.flush();
        if (!out) throw UserError(fmt::format("{}: write failed", what), "write_failed");
    }
    target.commit();
}

void add_calibrate(CLI::App& app) {
    struct Opts {
        CampaignSource source;
        std::string output;
        bool json = false, force = false;
        analysis::teq::Limits limits;
        analysis::teq::Options options;
    };
    auto o = std::make_shared<Opts>();
    auto* cmd = app.add_subcommand("calibrate", "Fit each zone's heat-transfer coefficient h_cal (W/m²K) for the equivalent "
                                                "temperature from a calibration campaign in a uniform, still environment");
    add_campaign_source_options(cmd, o->source);
    cmd->add_option("-o,--output", o->output, "The calibration file to write (JSON, docs/formats.md section 7; new, or with --force)")
        ->required();
    cmd->add_flag("--force", o->force, "Replace an existing calibration file");
    cmd->add_flag("--json", o->json, "Print the calibration document instead of the table");
    cmd->add_option("--max-wall-air-k", o->limits.max_wall_air_difference_k,
                    "Largest |wall - air| temperature difference (K) a calibration trial may have")
        ->check(CLI::Range(0.0, 5.0))
        ->capture_default_str();
    cmd->add_option("--max-air-speed", o->limits.max_air_speed_m_s, "Largest air speed (m/s) a calibration trial may have")
        ->check(CLI::Range(0.0, 1.0))
        ->capture_default_str();
    cmd->add_option("--draws", o->options.monte_carlo_draws, "Monte Carlo draws for the Type B uncertainty")
        ->check(CLI::Range(100, 1000000))
        ->capture_default_str();
    cmd->footer("Every trial's steady window must show air = wall within --max-wall-air-k and still air below\n"
                "--max-air-speed (our limits, docs/comfort.md); otherwise nothing is written and the case is named.\n"
                "Example: manikin calibrate teq-cal-20261129 -o manikin-teq-2026-11.json");
    cmd->callback([o] {
        ExportTarget target(o->output, ExportShape::file, o->force, source_inputs(o->source));
        const analysis::Campaign campaign = read_campaign_source(o->source);
        for (const auto& w : campaign.warnings) spdlog::warn("{}", w);
        analysis::teq::Calibration c;
        try {
            c = analysis::teq::calibrate(campaign, analysis::analyze_campaign(campaign), o->limits, o->options);
        } catch (const std::invalid_argument& e) {
            throw UserError(e.what(), "calibration_refused");
        }
        c.program = std::string("manikind ") + MANIKIND_VERSION;
        c.created_utc = analysis::iso_utc_ms(
            std::chrono::duration_cast<std::chrono::nanoseconds>(std::chrono::system_clock::now().time_since_epoch()).count());
        const auto doc = analysis::teq::to_json(c);
        write_target(target, doc.dump(2) + "\n", o->output);
        if (o->json) {
            std::printf("%s\n", doc.dump(2).c_str());
            return;
        }
        spdlog::info("wrote {}", o->output);
        std::printf("%s", analysis::teq::to_text(c).c_str());
    });
}

void add_teq(CLI::App& app) {
    struct Opts {
        CampaignSource source;
        std::string calibration, ranges, plot, report, hdf5;
        bool json = false, force = false;
        analysis::teq::Options options;
    };
    auto o = std::make_shared<Opts>();
    auto* cmd = app.add_subcommand("teq", "Equivalent temperature (ISO 14505-2) per zone, region and whole body, with 95 % "
                                          "intervals and a comfort-zone diagram");
    add_campaign_source_options(cmd, o->source);
    cmd->add_option("--calibration", o->calibration, "The calibration file `manikin calibrate` wrote")->required();
    cmd->add_option("--ranges", o->ranges, "The lab's neutral ranges: CSV part,cold_limit_c,warm_limit_c (part: a zone, a "
                                           "region or whole_body); without it, placeholders (docs/comfort.md)");
    cmd->add_option("--plot", o->plot, "Write the comfort-zone diagram (SVG) to this file (new, or with --force)");
    cmd->add_option("--report", o->report, "Write a page for the reader (HTML with the diagram inline): campaign, calibration, "
                                           "when, the standard, the whole body and regions per case, every zone, notes");
    cmd->add_option("--hdf5", o->hdf5, "Write teq per case (zones, regions, whole body with u_A, u_B, U95) and the JSON "
                                       "document to this HDF5 file (manikin-teq-hdf5/1, docs/formats.md 7.3)");
    cmd->add_flag("--force", o->force, "Replace an existing diagram, report or HDF5 file");
    cmd->add_flag("--constant-h", [o](std::int64_t) { o->options.curved_h = false; },
                  "Use each zone's h_cal as one constant, as ISO 14505-2 writes it (default: read from the calibration's curve "
                  "at the zone's own temperature difference, docs/comfort.md)");
    cmd->add_flag("--json", o->json, "Print one JSON document (docs/formats.md section 7) instead of the table");
    cmd->add_option("--draws", o->options.monte_carlo_draws, "Monte Carlo draws for the Type B uncertainty")
        ->check(CLI::Range(100, 1000000))
        ->capture_default_str();
    cmd->footer("teq = t_skin - q / h_cal per zone; regions and whole body as the uniform temperature in which they lose\n"
                "their zones' heat (docs/comfort.md). Each case of the campaign is one environment.\n"
                "Example: manikin teq cabin-20261129 --calibration manikin-teq-2026-11.json --ranges lab-ranges.csv --plot teq.svg");
    cmd->callback([o] {
        // Both outputs are checked before anything is read (docs/cli.md, the output guard).
        std::optional<ExportTarget> target, report_target, hdf5_target;
        auto inputs = source_inputs(o->source);
        inputs.emplace_back(o->calibration);
        if (!o->ranges.empty()) inputs.emplace_back(o->ranges);
        if (!o->plot.empty()) target.emplace(o->plot, ExportShape::file, o->force, inputs);
        if (!o->report.empty()) {
            if (o->report == o->plot) throw UserError(fmt::format("--report and --plot name the same file: {}", o->report));
            report_target.emplace(o->report, ExportShape::file, o->force, inputs);
        }
        if (!o->hdf5.empty()) {
            if (o->hdf5 == o->plot || o->hdf5 == o->report)
                throw UserError(fmt::format("--hdf5 names the same file as --{}: {}", o->hdf5 == o->plot ? "plot" : "report", o->hdf5));
            hdf5_target.emplace(o->hdf5, ExportShape::file, o->force, inputs);
        }
        analysis::teq::Calibration calibration;
        analysis::teq::NeutralRanges ranges;
        const analysis::Campaign campaign = read_campaign_source(o->source);
        for (const auto& w : campaign.warnings) spdlog::warn("{}", w);
        try {
            calibration = analysis::teq::read_calibration(o->calibration);
            ranges = o->ranges.empty() ? analysis::teq::placeholder_ranges(campaign.zone_map) : analysis::teq::read_ranges(o->ranges);
        } catch (const analysis::InputError& e) {
            throw UserError(e.what());
        }
        analysis::teq::Result r;
        try {
            r = analysis::teq::compute(campaign, analysis::analyze_campaign(campaign), calibration, ranges, o->options);
        } catch (const std::invalid_argument& e) {
            throw UserError(e.what());
        }
        if (ranges.placeholder) r.warnings.push_back("neutral ranges are placeholders (21-26 °C), not from a source: give --ranges");
        if (target) {
            write_target(*target, analysis::plot::to_svg(analysis::teq::comfort_figure(r)), o->plot);
            spdlog::info("wrote {}", o->plot);
        }
        if (report_target) {
            const std::string when = analysis::iso_utc_ms(
                std::chrono::duration_cast<std::chrono::nanoseconds>(std::chrono::system_clock::now().time_since_epoch()).count());
            write_target(*report_target, analysis::teq::report_html(r, when, std::string("manikin ") + MANIKIND_VERSION), o->report);
            spdlog::info("wrote {}", o->report);
        }
        if (hdf5_target) {
            write_teq_hdf5(hdf5_target->staging(), r, analysis::teq::to_json(r));
            hdf5_target->commit();
            spdlog::info("wrote {}", o->hdf5);
        }
        if (o->json)
            std::printf("%s\n", analysis::teq::to_json(r).dump(2).c_str());
        else
            std::printf("%s", analysis::teq::to_text(r).c_str());
    });
}

}  // namespace

void add_comfort_commands(CLI::App& app) {
    if (building("calibrate")) add_calibrate(app);
    if (building("teq")) add_teq(app);
}

}  // namespace manikind::cli
