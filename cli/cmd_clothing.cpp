// `manikin clothing <campaign>`: a garment's thermal insulation and evaporative resistance from a
// standard clothing test (ASTM F1291, ISO 15831, ASTM F2370; analysis/clothing.hpp), with 95 %
// intervals, the replicate criterion and a one-page report per ensemble.
#include <cstdio>
#include <map>
#include <ctime>
#include <cctype>
#include <algorithm>
#include <filesystem>
#include <fstream>
#include <memory>
#include <optional>
#include <stdexcept>
#include <string>

#include <fmt/core.h>
#include <spdlog/spdlog.h>

#include "analysis/analyze.hpp"
#include "analysis/clothing.hpp"
#include "base/text.hpp"
#include "base/toml_input.hpp"
#include "base/user_error.hpp"
#include "cli/campaign_source.hpp"
#include "cli/commands.hpp"
#include "store/export_target.hpp"

namespace manikind::cli {

namespace {

std::string base64(const std::string& bytes) {
    static constexpr char table[] = "ABCDEFGHIJKLMNOPQRSTUVWXYZabcdefghijklmnopqrstuvwxyz0123456789+/";
    std::string out;
    std::size_t i = 0;
    for (; i + 2 < bytes.size(); i += 3) {
        const unsigned v = (static_cast<unsigned char>(bytes[i]) << 16) | (static_cast<unsigned char>(bytes[i + 1]) << 8) |
                           static_cast<unsigned char>(bytes[i + 2]);
        for (int s : {18, 12, 6, 0}) out += table[(v >> s) & 63];
    }
    if (i < bytes.size()) {
        unsigned v = static_cast<unsigned char>(bytes[i]) << 16;
        if (i + 1 < bytes.size()) v |= static_cast<unsigned char>(bytes[i + 1]) << 8;
        out += table[(v >> 18) & 63];
        out += table[(v >> 12) & 63];
        out += i + 1 < bytes.size() ? table[(v >> 6) & 63] : '=';
        out += '=';
    }
    return out;
}

// `--report-info report.toml` (docs/clothing.md, "The report"): [lab] and [report] tables of text.
analysis::clothing::ReportInfo read_report_info(const std::string& file) {
    const std::filesystem::path path(file);
    const auto root = toml_input::parse(toml_input::read_text_file(path, "a report-info TOML file"), file);
    analysis::clothing::ReportInfo info;
    std::string logo;
    const std::map<std::string, std::map<std::string, std::string*>> keys = {
        {"lab", {{"name", &info.lab_name}, {"address", &info.lab_address}, {"accreditation", &info.accreditation},
                 {"logo", &logo}, {"manikin", &info.manikin}, {"chamber", &info.chamber}}},
        {"report", {{"number", &info.report_number}, {"date", &info.report_date}, {"customer", &info.customer},
                    {"sample", &info.sample}, {"operator", &info.operator_name}, {"approver", &info.approver},
                    {"insulation_standard", &info.insulation_standard}, {"evaporative_standard", &info.evaporative_standard}}}};
    for (const auto& [name, node] : root) {
        const auto table = keys.find(std::string(name.str()));
        if (table == keys.end() || !node.is_table())
            throw UserError(fmt::format("{}: {}: expected [lab] or [report]", toml_input::where(file, name.source()), name.str()));
        for (const auto& [key, value] : *node.as_table()) {
            const auto field = table->second.find(std::string(key.str()));
            if (field == table->second.end()) {
                std::string known;
                for (const auto& [k, p] : table->second) known += (known.empty() ? "" : ", ") + k;
                throw UserError(fmt::format("{}: {}.{}: unknown key (known: {})", toml_input::where(file, key.source()), name.str(),
                                            key.str(), known));
            }
            if (!value.is_string())
                throw UserError(fmt::format("{}: {}.{}: expected text", toml_input::where(file, value), name.str(), key.str()));
            const std::string text = value.as_string()->get();
            if (text.size() > 400 || !is_utf8(text))
                throw UserError(fmt::format("{}: {}.{}: expected UTF-8 text of at most 400 bytes", toml_input::where(file, value),
                                            name.str(), key.str()));
            *field->second = text;
        }
    }
    if (!info.report_date.empty() && (info.report_date.size() != 10 || info.report_date[4] != '-' || info.report_date[7] != '-'))
        throw UserError(fmt::format("{}: report.date: expected YYYY-MM-DD, found '{}'", file, info.report_date));
    if (info.report_date.empty()) {
        const std::time_t now = std::time(nullptr);
        std::tm utc{};
        gmtime_r(&now, &utc);
        info.report_date = fmt::format("{:04}-{:02}-{:02}", utc.tm_year + 1900, utc.tm_mon + 1, utc.tm_mday);
    }
    if (!logo.empty()) {
        // Embedded, so the page loads nothing from elsewhere: PNG, JPEG or SVG of at most 300 kB.
        const std::filesystem::path logo_path = path.parent_path() / logo;
        std::string ext = logo_path.extension().string();
        std::transform(ext.begin(), ext.end(), ext.begin(), [](unsigned char c) { return static_cast<char>(std::tolower(c)); });
        const char* mime = ext == ".png" ? "image/png" : ext == ".jpg" || ext == ".jpeg" ? "image/jpeg" : ext == ".svg" ? "image/svg+xml" : nullptr;
        if (!mime) throw UserError(fmt::format("{}: lab.logo: '{}' is not a .png, .jpg or .svg file", file, logo));
        const std::string bytes = toml_input::read_text_file(logo_path, "a logo image", 300 * 1024);
        info.logo_data_uri = fmt::format("data:{};base64,{}", mime, base64(bytes));
    }
    return info;
}

}  // namespace

void add_clothing_command(CLI::App& app) {
    struct Opts {
        CampaignSource source;
        std::string baseline, report, redress_from, report_info;
        bool json = false, force = false;
        bool require_flux_stability = false;
        bool skin_steadiness_only = false;
        analysis::clothing::Options options;
        // The replicate criteria in percent, as every output prints them (5 means 5 %).
        double cv_limit_insulation_pct = 5.0, cv_limit_evaporative_pct = 10.0;
    };
    auto o = std::make_shared<Opts>();
    auto* cmd = app.add_subcommand("clothing", "Clothing insulation (It, Icle, Icl) and evaporative resistance (Ret, Recl, "
                                               "im) from a standard manikin test, with 95 % intervals");
    add_campaign_source_options(cmd, o->source);
    cmd->add_option("--baseline", o->baseline,
                    "A campaign with the nude manikin's trials (ensemble \"nude\"), when this one has none: a folder, or "
                    "with --db a campaign in the same database");
    cmd->add_option("--redress-from", o->redress_from,
                    "An earlier test of this lab with replicates (a folder, or with --db a campaign there): where an "
                    "ensemble has one replicate, its Type A is the re-dressing scatter pooled from that test's ensembles "
                    "(without it a 1-replicate interval excludes re-dressing and says so)");
    cmd->add_flag("--json", o->json, "Print one JSON document (docs/formats.md section 5) instead of the table");
    cmd->add_option("--report", o->report, "Write the one-page-per-ensemble report (HTML with SVG) to this file (new; "
                                           "never inside a campaign folder it reads, never over a database)");
    cmd->add_flag("--force", o->force, "Replace an existing report file");
    cmd->add_option("--report-info", o->report_info,
                    "A TOML file with the report's header and identity: [lab] name, address, accreditation, logo (a .png, "
                    ".jpg or .svg beside it), manikin, chamber; [report] number, date, customer, sample, operator, approver, "
                    "insulation_standard, evaporative_standard (with edition, e.g. \"ASTM F1291-16\")")
        ->check(CLI::ExistingFile);
    cmd->add_option("--cv-limit-insulation", o->cv_limit_insulation_pct,
                    "Largest coefficient of variation of the re-dressed replicates' total insulation, in % (5 = 5 %)")
        ->check(CLI::Range(0.1, 100.0))
        ->capture_default_str();
    cmd->add_option("--cv-limit-evaporative", o->cv_limit_evaporative_pct,
                    "Largest coefficient of variation of the replicates' total evaporative resistance, in % (10 = 10 %)")
        ->check(CLI::Range(0.1, 100.0))
        ->capture_default_str();
    cmd->add_flag("--skin-steadiness-only", o->skin_steadiness_only,
                  "Judge steady state by skin temperature alone (the paper's rule). By default a trial is also steady in "
                  "heat loss as the clothing standards ask: the whole-body heat loss moves at most 3 % and the mean skin "
                  "temperature 0.1 °C over the 30-min window (docs/clothing.md, \"The stop rule\")");
    cmd->add_flag("--require-flux-stability", o->require_flux_stability,
                  "Stricter still: every zone's flux drift and scatter over the window within manikin analyze's limits "
                  "(2 W/m², 5 W/m²)");
    cmd->add_option("--fabric-resistance", o->options.fabric_resistance_m2k_w,
                    "The wet skin fabric's thermal resistance, m²K/W: the skin's vapour pressure is taken at the fabric's "
                    "surface, q R below the sensor (default 0: at the sensor, where Ret reads high)")
        ->check(CLI::Range(0.0, 0.2))
        ->capture_default_str();
    cmd->add_option("--draws", o->options.monte_carlo_draws, "Monte Carlo draws for the Type B uncertainty")
        ->check(CLI::Range(100, 1000000))
        ->capture_default_str();
    cmd->footer("Trials take part when campaign.json names their `ensemble` (an id of `ensembles`, or \"nude\") and\n"
                "`test` (\"insulation\" or \"evaporative\"); docs/clothing.md has the equations, the standards' conditions\n"
                "and where each number comes from. Exit status 5 when a trial was left out (not steady by the rule, or\n"
                "not analysed; the table says which and why), 0 otherwise, even when a replicate criterion fails (reported).\n"
                "Example: manikin clothing lab-day --baseline nude-baseline --report report.html\n"
                "         manikin clothing quick-check --redress-from lab-day   # one replicate, the lab's re-dressing scatter\n"
                "         manikin clothing --db manikind.db --campaign jackets-20261126 --json");
    cmd->callback([o] {
        // The report is checked before anything is read (docs/cli.md, "Reading a database, writing
        // an export"): never in a campaign folder read (it could replace campaign.json or a trial's
        // CSV), never on a database read or any database's companion, links, devices, and an
        // existing file only with --force; written whole, then renamed into place.
        std::optional<ExportTarget> target;
        if (!o->report.empty()) {
            std::vector<std::filesystem::path> inputs = source_inputs(o->source);
            for (const std::string* other : {&o->baseline, &o->redress_from}) {
                if (other->empty()) continue;
                CampaignSource from = o->source;
                from.campaign = *other;
                for (auto& p : source_inputs(from)) inputs.push_back(std::move(p));
            }
            if (!o->report_info.empty()) inputs.emplace_back(o->report_info);  // never over what it reads
            target.emplace(o->report, ExportShape::file, o->force, inputs);
        }
        analysis::clothing::ReportInfo info = o->report_info.empty() ? analysis::clothing::ReportInfo{} : read_report_info(o->report_info);
        const analysis::Campaign campaign = read_campaign_source(o->source);
        for (const auto& w : campaign.warnings) spdlog::warn("{}", w);
        // The standard a test followed is the campaign's choice ([standards] in its plan); the
        // report-info file only fills in what an older campaign did not say.
        for (auto [test, field] : {std::pair{"insulation", &info.insulation_standard}, std::pair{"evaporative", &info.evaporative_standard}}) {
            const auto chosen = campaign.standards.find(test);
            if (chosen == campaign.standards.end()) continue;
            if (!field->empty() && *field != chosen->second)
                spdlog::warn("{}: report.{}_standard \"{}\" is not what campaign {} followed; the report names the campaign's \"{}\"",
                             o->report_info, test, *field, campaign.name, chosen->second);
            *field = chosen->second;
        }
        analysis::AnalysisOptions analysis_options;
        analysis_options.steady.require_flux_stability = o->require_flux_stability;
        analysis_options.steady.require_heat_loss_stability = !o->skin_steadiness_only;
        const auto result = analysis::analyze_campaign(campaign, analysis_options);
        std::optional<analysis::Campaign> baseline;
        std::optional<analysis::CampaignResult> baseline_result;
        if (!o->baseline.empty()) {
            CampaignSource from = o->source;
            from.campaign = o->baseline;
            try {
                baseline = read_campaign_source(from);
            } catch (const UserError& e) {
                // Named as the baseline: "no campaign 'nude'" alone read as if the tested campaign were missing.
                throw UserError(fmt::format("--baseline '{}' (the nude manikin's campaign): {}", o->baseline, e.what()), e.code(),
                                e.status(), e.details());
            }
            baseline_result = analysis::analyze_campaign(*baseline, analysis_options);
        }
        analysis::clothing::Options options = o->options;
        options.cv_limit_insulation = o->cv_limit_insulation_pct / 100.0;
        options.cv_limit_evaporative = o->cv_limit_evaporative_pct / 100.0;
        if (!o->redress_from.empty()) {
            CampaignSource from = o->source;
            from.campaign = o->redress_from;
            try {
                const analysis::Campaign earlier = read_campaign_source(from);
                const auto earlier_result = analysis::analyze_campaign(earlier, analysis_options);
                analysis::clothing::Options plain = options;
                plain.monte_carlo_draws = 100;  // only its replicates are used
                options.redressing = analysis::clothing::redressing_scatter(
                    analysis::clothing::compute(earlier, earlier_result, nullptr, nullptr, plain));
            } catch (const UserError& e) {
                throw UserError(fmt::format("--redress-from '{}' (the earlier test with replicates): {}", o->redress_from, e.what()),
                                e.code(), e.status(), e.details());
            } catch (const std::invalid_argument& e) {
                throw UserError(fmt::format("--redress-from '{}': {}", o->redress_from, e.what()));
            }
        }
        analysis::clothing::Result r;
        try {
            r = analysis::clothing::compute(campaign, result, baseline ? &*baseline : nullptr,
                                            baseline_result ? &*baseline_result : nullptr, options);
        } catch (const std::invalid_argument& e) {
            throw UserError(e.what());
        }
        if (target) {
            {
                std::ofstream out(target->staging(), std::ios::binary | std::ios::trunc);
                out << analysis::clothing::to_html(r, campaign.zone_map, &campaign, info);
                out.flush();
                if (!out) throw UserError(fmt::format("--report {}: write failed", o->report), "write_failed");
            }
            target->commit();
            spdlog::info("wrote {}", o->report);
        }
        if (o->json)
            std::printf("%s\n", analysis::clothing::to_json(r).dump(2).c_str());
        else
            std::printf("%s", analysis::clothing::to_text(r).c_str());
        // Trials left out change what the results stand on: the exit status says so (docs/cli.md).
        if (!r.left_out.empty() || !r.without_result.empty())
            throw UserError::verdict_in_output(fmt::format(
                "{} trial{} left out{}: see LEFT OUT in the table (or left_out in --json)", r.left_out.size(),
                r.left_out.size() == 1 ? "" : "s",
                r.without_result.empty() ? "" : fmt::format(", {} ensemble{} without a result", r.without_result.size(),
                                                            r.without_result.size() == 1 ? "" : "s")));
    });
}

}  // namespace manikind::cli
