// The planner's campaigns (`--power`, docs/reconcile.md "Detection limits"): a campaign of the
// same design drawn anew from what the recorded one estimated, with an effect concealed. The
// planner runs reconcile itself on these, so they must be campaigns reconcile can read as it reads
// a recording: the same cases and zones, the asked-for replicates, the recorded scatter's size,
// and reproducible from their seed.
#include <catch2/catch.hpp>

#include <algorithm>
#include <cmath>
#include <random>

#include "analysis/reconcile/evidence.hpp"
#include "analysis/reconcile/report_output.hpp"
#include "tests/reconcile/synthetic_campaign.hpp"

using namespace manikind;
namespace rc = manikind::analysis::reconcile;
namespace tw = manikind::physics::twin;
namespace ev = manikind::analysis::reconcile::evidence;

namespace {

std::unique_ptr<rc::ForwardModel> recorded(unsigned seed, int replicates = 3) {
    test::SyntheticOptions o;
    o.seed = seed;
    o.replicates = replicates;
    return rc::make_twin_model(test::make_campaign(tw::TwinVersion{"world", {}}, o), tw::TwinVersion{});
}

double mean_zone_sd(const rc::NoiseModel& n) {
    double sum = 0.0;
    for (const auto& [zone, sd] : n.zone_sd_w_m2) sum += sd;
    return sum / static_cast<double>(n.zone_sd_w_m2.size());
}

}  // namespace

TEST_CASE("planning: a simulated campaign has the recorded design, the asked-for replicates and the recorded scatter, "
          "and its seed reproduces it", "[reconcile][power]") {
    const auto model = recorded(11);
    const rc::Options opt;
    const auto simulator = model->campaign_simulator(opt.instruments, opt.probe_shared_fraction);
    REQUIRE(simulator);
    const auto a = simulator->draw({}, 5, 42);
    REQUIRE(a);
    REQUIRE(a->points().size() == model->points().size());
    for (std::size_t i = 0; i < a->points().size(); ++i) {
        CHECK(a->points()[i].case_id == model->points()[i].case_id);
        CHECK(a->points()[i].zone == model->points()[i].zone);
    }
    const auto na = a->noise_model(opt.instruments, opt.probe_shared_fraction);
    for (int reps : na.point_replicates) CHECK(reps == 5);
    // The per-zone scatter estimated from the simulated replicates is the recorded one's size
    // (both estimates scatter; a factor of 1.5 either way would be a wrong draw).
    const auto nm = model->noise_model(opt.instruments, opt.probe_shared_fraction);
    CHECK(mean_zone_sd(na) == Approx(mean_zone_sd(nm)).epsilon(0.35));
    // Reproducible from the seed, different with another.
    const auto again = simulator->draw({}, 5, 42);
    const auto other = simulator->draw({}, 5, 43);
    CHECK(again->points()[7].q_exp == a->points()[7].q_exp);
    CHECK(other->points()[7].q_exp != a->points()[7].q_exp);
}

TEST_CASE("planning: an effect concealed in simulated campaigns shows in them (a large humidity buoyancy is named) and "
          "none is claimed without one", "[reconcile][power][proof]") {
    const auto model = recorded(12);
    rc::Options opt;
    opt.null_simulations = 400;
    const tw::Term gamma{"humidity_buoyancy", {{"gamma", 146.0}}, "", {}};
    const auto simulator = model->campaign_simulator(opt.instruments, opt.probe_shared_fraction);
    const auto with = simulator->draw({gamma}, 3, 7);
    const auto r = rc::reconcile(*with, opt);
    INFO(r.statement);
    REQUIRE(r.explanation);
    CHECK(r.explanation->label == "humidity_buoyancy");
    CHECK(std::abs(r.explanation->values[0] - 146.0) <= 3.0 * r.explanation->uncertainties[0] + 5.0);
    const auto without = simulator->draw({}, 3, 7);
    CHECK_FALSE(rc::reconcile(*without, opt).explanation);
}

TEST_CASE("planning: a campaign with one replicate per case and no carried scatter cannot be simulated (nothing to draw "
          "the scatter from), and --power falls back to the fast model", "[reconcile][power]") {
    const auto model = recorded(13, 1);
    const rc::Options opt;
    CHECK_FALSE(model->campaign_simulator(opt.instruments, opt.probe_shared_fraction));
    rc::PowerOptions po;
    po.terms = {"wall_offset"};
    const auto plan = rc::detection_limits(*model, opt, {3}, po);
    for (const auto& d : plan.limits) CHECK(d.method == "fast model");
    po.terms = {"no_such_term"};
    CHECK_THROWS_AS(rc::detection_limits(*model, opt, {3}, po), std::invalid_argument);
}

TEST_CASE("planning: a candidate planned alone is judged against the whole family, with reconcile's own claim threshold",
          "[reconcile][power][proof]") {
    // `--power-terms` once built the family's null from the planned candidates only: a lower
    // threshold than reconcile's, so limits reconcile would not reach.
    const auto model = recorded(14);
    rc::Options opt;
    opt.null_simulations = 400;
    rc::PowerOptions po;
    po.campaigns = 0;  // the fast model: the threshold is what is compared
    po.terms = {"wall_offset"};
    const auto one = rc::detection_limits(*model, opt, {3}, po);
    po.terms = {};
    const auto all = rc::detection_limits(*model, opt, {3}, po);
    REQUIRE(one.claim_threshold.count(3));
    CHECK(one.claim_threshold.at(3) == all.claim_threshold.at(3));
    for (const auto& d : one.limits) CHECK(d.label == "wall_offset");
    CHECK(all.limits.size() > one.limits.size());
    CHECK(one.claim_threshold.at(3) == Approx(rc::reconcile(*model, opt).null_threshold).epsilon(1e-9));
}

TEST_CASE("planning: where evidence is beyond the null but no term passes and too many zones stand out, the report says "
          "unexplained, never that the twin agrees", "[reconcile][power][proof]") {
    // Found by the planner: a small humidity buoyancy shows at the isothermal cases' kink as many
    // zones' offsets, no single term passing. The statement fell through to "The twin agrees with
    // the recordings within their noise" while quoting an evidence beyond the null. (At gamma 30
    // until the per-trial errors' loadings became local secants, 2026-11-27: there the path is
    // not taken in these 12 draws, at 20 it is.)
    const auto model = recorded(12);
    rc::Options opt;
    opt.null_simulations = 400;
    // The named list only: with the generated hypotheses (issue 61) one of them passes the null in
    // these draws (a vertical gradient, a drier side), ambiguous with the buoyancy, so the
    // statement under test is not reached; the statement's logic is the same with either family.
    opt.hypotheses = "none";
    const tw::Term gamma{"humidity_buoyancy", {{"gamma", 20.0}}, "", {}};
    const auto simulator = model->campaign_simulator(opt.instruments, 1.0);
    int unexplained = 0;
    for (std::uint64_t seed = 1; seed <= 12; ++seed) {
        const auto r = rc::reconcile(*simulator->draw({gamma}, 3, seed), opt);
        INFO(r.statement);
        if (r.consistent_before) CHECK(r.family_evidence <= r.null_threshold);
        if (r.family_evidence > r.null_threshold) CHECK_THAT(r.statement, !Catch::Contains("agrees"));
        if (r.statement.find("not confined to a few zones") != std::string::npos) ++unexplained;
    }
    CHECK(unexplained >= 1);  // the path is exercised, not only allowed
}

TEST_CASE("planning: a drawn lab's probes are off within their specification's limit (rectangular, GUM 4.3.7), and the "
          "errors it reports are the ones in its data", "[reconcile][power]") {
    const auto model = recorded(15);
    const rc::Options opt;
    const auto simulator = model->campaign_simulator(opt.instruments, 1.0);
    REQUIRE(simulator);
    const double air_limit = opt.instruments.at("air_temp_c").limit(30.0);
    const double wall_limit = opt.instruments.at("wall_temp_c").limit(30.0);
    // 200 labs: a normal draw of the same u (a / sqrt 3) passes the limit in about 8 % of them.
    int beyond = 0, wide = 0;
    double largest_air = 0.0;
    std::uint64_t largest_seed = 0;
    std::vector<tw::Term> calibration;
    for (std::uint64_t seed = 1; seed <= 200; ++seed) {
        REQUIRE(simulator->draw({}, 1, seed, &calibration));
        REQUIRE(calibration.size() == 2);
        CHECK(calibration[0].name == "air_temp_bias");
        CHECK(calibration[1].name == "wall_offset");
        const double air = calibration[0].parameters.at("bias_c"), wall = calibration[1].parameters.at("delta_c");
        beyond += std::abs(air) > air_limit || std::abs(wall) > wall_limit ? 1 : 0;
        wide += std::abs(air) > 0.6 * air_limit ? 1 : 0;  // rectangular: 40 % of labs
        if (std::abs(air) > largest_air) largest_air = std::abs(air), largest_seed = seed;
    }
    CHECK(beyond == 0);
    CHECK(wide >= 50);
    // The reported terms correct the drawn campaign: the twin with them fits its fluxes better than
    // the twin as given, and better than with their signs turned.
    const auto m = simulator->draw({}, 3, largest_seed, &calibration);
    std::vector<tw::Term> turned = calibration;
    turned[0].parameters["bias_c"] *= -1.0;
    turned[1].parameters["delta_c"] *= -1.0;
    auto mse = [&](const std::vector<tw::Term>& terms) {
        const auto q = m->predict(terms);
        double s = 0.0;
        for (std::size_t i = 0; i < q.size(); ++i) s += std::pow(m->points()[i].q_exp - q[i], 2);
        return s / static_cast<double>(q.size());
    };
    INFO("air bias " << calibration[0].parameters.at("bias_c") << " degC, wall " << calibration[1].parameters.at("delta_c"));
    CHECK(mse(calibration) < mse({}));
    CHECK(mse({}) < mse(turned));
}

TEST_CASE("planning: the verdict names the concealed term alone or beside the lab's own probe error within its interval, "
          "nothing else", "[reconcile][power]") {
    const auto library = rc::candidate_library({});
    auto term = [&](const std::string& name) {
        const auto it = std::find_if(library.begin(), library.end(), [&](const auto& c) { return c.term == name; });
        REQUIRE(it != library.end());
        return *it;
    };
    auto report = [](std::vector<rc::CandidateTerm> terms, std::vector<double> lo, std::vector<double> hi) {
        rc::Report r;
        rc::CandidateResult e;
        for (std::size_t k = 0; k < terms.size(); ++k) e.label += (k ? " + " : "") + terms[k].label();
        e.terms = std::move(terms);
        for (std::size_t k = 0; k < lo.size(); ++k) e.values.push_back(0.5 * (lo[k] + hi[k]));
        e.interval_lo = std::move(lo);
        e.interval_hi = std::move(hi);
        r.explanation = e;
        return r;
    };
    const auto textile = term("textile_resistance"), air = term("air_temp_bias"), gamma = term("humidity_buoyancy");
    const std::vector<tw::Term> lab = {{"air_temp_bias", {{"bias_c", -0.15}}, "", {}}, {"wall_offset", {{"delta_c", 0.07}}, "", {}}};
    CHECK_FALSE(rc::names_concealed(rc::Report{}, "textile_resistance", lab));
    CHECK(rc::names_concealed(report({textile}, {0.0008}, {0.0012}), "textile_resistance", lab));
    CHECK_FALSE(rc::names_concealed(report({gamma}, {10.0}, {30.0}), "textile_resistance", lab));
    // Beside the lab's air probe error, its interval holding it: both found.
    CHECK(rc::names_concealed(report({air, textile}, {-0.19, 0.0008}, {-0.12, 0.0012}), "textile_resistance", lab));
    // An air bias the lab's probe does not have is a wrong partner.
    CHECK_FALSE(rc::names_concealed(report({air, textile}, {0.10, 0.0008}, {0.20, 0.0012}), "textile_resistance", lab));
    CHECK_FALSE(rc::names_concealed(report({air, textile}, {-0.19, 0.0008}, {-0.12, 0.0012}), "textile_resistance", {}));
    // A physics partner is not a calibration error.
    CHECK_FALSE(rc::names_concealed(report({gamma, textile}, {10.0, 0.0008}, {30.0, 0.0012}), "textile_resistance", lab));
}

TEST_CASE("planning: reconcile asked for the verdict alone gives the verdict the whole report gives, and stops early "
          "where another term wins and no pair could name the concealed one",
          "[planning][power][proof]") {
    const auto model = recorded(15);
    rc::Options opt;
    opt.null_simulations = 400;
    const auto simulator = model->campaign_simulator(opt.instruments, 1.0);
    REQUIRE(simulator);
    const tw::Term gamma{"humidity_buoyancy", {{"gamma", 146.0}}, "", {}};
    int stopped = 0;
    for (const std::string label : {"humidity_buoyancy", "textile_resistance"}) {
        for (std::uint64_t seed : {99u, 100u}) {
            std::vector<tw::Term> calibration;
            const auto lab = simulator->draw({gamma}, 3, seed, &calibration);
            const rc::Report whole = rc::reconcile(*lab, opt);
            rc::Options verdict = opt;
            verdict.verdict_for = rc::Options::VerdictFor{label, calibration};
            const rc::Report quick = rc::reconcile(*lab, verdict);
            INFO(label << " on lab " << seed << ": " << whole.statement);
            CHECK(rc::names_concealed(quick, label, calibration) == rc::names_concealed(whole, label, calibration));
            if (quick.statement.find("no pair tried could name") != std::string::npos) {
                ++stopped;
                CHECK(label != "humidity_buoyancy");
                continue;
            }
            // Stopped once the claim was settled: the claim itself, as the whole report gives it.
            REQUIRE(quick.explanation.has_value() == whole.explanation.has_value());
            if (whole.explanation) {
                CHECK(quick.explanation->label == whole.explanation->label);
                CHECK(quick.explanation->values == whole.explanation->values);
                CHECK(quick.explanation->interval_lo == whole.explanation->interval_lo);
                CHECK(quick.explanation->interval_hi == whole.explanation->interval_hi);
            }
        }
    }
    // A large gamma wins in both labs; in one the textile term cannot be named and it stops there
    // (in the other the textile term and the air bias are both strong: their pair could name it).
    CHECK(stopped >= 1);
}

TEST_CASE("planning: a bracket around 80 % that climbs steeply is tried once more at its geometric middle, a fine one "
          "is read as it is",
          "[planning][power]") {
    auto pt = [](double value, int named, int campaigns) {
        rc::PowerPoint p;
        p.value = value;
        p.named = p.named_alone = named;
        p.campaigns = campaigns;
        return p;
    };
    // The wall's bracket in the bench's plan (2026-11-27): 27/40 at 1.125 °C, 40/40 at 1.406 °C.
    const auto wall = rc::coarse_bracket_middle({pt(0.9, 12, 40), pt(1.125, 27, 40), pt(1.406, 40, 40)}, 0.0, 0.8);
    REQUIRE(wall);
    CHECK(*wall == Approx(std::sqrt(1.125 * 1.406)).epsilon(1e-12));
    // Below the null (a parameter that walks down): the middle is taken in distance from the null.
    const auto down = rc::coarse_bracket_middle({pt(0.96, 4, 20), pt(0.90, 19, 20)}, 1.0, 0.8);
    REQUIRE(down);
    CHECK(*down == Approx(1.0 - std::sqrt(0.04 * 0.10)).epsilon(1e-12));
    // From none to most; and 15/20 to 20/20 (a quarter, but saturated: the logit line through an
    // end named in all leans on the half campaign that keeps it finite).
    CHECK(rc::coarse_bracket_middle({pt(10.0, 0, 20), pt(12.5, 17, 20)}, 0.0, 0.8).has_value());
    CHECK(rc::coarse_bracket_middle({pt(10.0, 15, 20), pt(12.5, 20, 20)}, 0.0, 0.8).has_value());
    // 14/20 and 17/20: a bracket of 15 points, read as it is.
    CHECK_FALSE(rc::coarse_bracket_middle({pt(10.0, 14, 20), pt(12.5, 17, 20)}, 0.0, 0.8).has_value());
    // No bracket: everything named, or nothing reaching 80 %.
    CHECK_FALSE(rc::coarse_bracket_middle({pt(10.0, 17, 20), pt(12.5, 20, 20)}, 0.0, 0.8).has_value());
    CHECK_FALSE(rc::coarse_bracket_middle({pt(10.0, 3, 20), pt(12.5, 9, 20)}, 0.0, 0.8).has_value());
    // The bracket read is the one farthest from no effect (as the crossing is read): there, fine.
    CHECK_FALSE(rc::coarse_bracket_middle({pt(1.0, 0, 20), pt(2.0, 20, 20), pt(3.0, 15, 20), pt(4.0, 17, 20)}, 0.0, 0.8).has_value());
}

TEST_CASE("the plan's text says how far its limits held on independent campaigns, and that a fast model's are lower bounds",
          "[reconcile][power]") {
    rc::PowerReport plan;
    plan.campaign_replicates = 3;
    plan.replicates = {3};
    rc::DetectionLimit d;
    d.label = "wall_offset";
    d.parameter = "delta_c";
    d.replicates = 3;
    d.value = 1.26;
    d.method = "whole decision";
    d.tried = {{1.125, 25, 40, 24, {}, {}, 40}, {1.26, 32, 40, 32, {}, {}, 40}};
    plan.limits = {d};
    const std::string whole = rc::power_to_text(plan);
    CHECK_THAT(whole, Catch::Contains("checked by running reconcile itself on 40 campaigns"));
    CHECK_THAT(whole, Catch::Contains("pooled 78 %, in labs that set their chamber by their own probes"));
    plan.limits.front().tried.clear();
    plan.limits.front().method = "fast model";
    const std::string fast = rc::power_to_text(plan);
    CHECK_THAT(fast, Catch::Contains("read the limits as lower bounds"));
    CHECK_THAT(fast, !Catch::Contains("pooled 78 %"));
}

namespace {

// A plan's whole-decision verdicts for 40 drawn labs at three values tried, drawn here (not by the
// planner): lab i names the term at value v when its own latent draw falls under a share that
// climbs with v and, by `air_weight`, sinks with how far the lab's air probe erred.
struct SyntheticPlan {
    rc::DetectionLimit limit;
    std::vector<std::vector<rc::DrawnCalibrationError>> labs;
};
SyntheticPlan synthetic_plan(std::uint64_t seed, double air_weight) {
    std::mt19937_64 rng(seed);
    std::uniform_real_distribution<double> unit(0.0, 1.0), spec(-1.0, 1.0);
    SyntheticPlan s;
    const char* channels[] = {"air_temp_c", "air_rh_pct", "wall_temp_c", "heat_flux_offset", "heat_flux_gain"};
    const double limits[] = {0.2, 1.6, 0.5, 1.0, 0.03};
    std::vector<double> latent;
    for (int i = 0; i < 40; ++i) {
        std::vector<rc::DrawnCalibrationError> lab;
        for (int c = 0; c < 5; ++c) lab.push_back({channels[c], spec(rng), limits[c]});
        s.labs.push_back(lab);
        latent.push_back(unit(rng));
    }
    s.limit.label = "textile_resistance";
    s.limit.null_value = 0.0;
    s.limit.method = "whole decision";
    for (double v : {0.0008, 0.001, 0.00125}) {
        rc::PowerPoint pt;
        pt.value = v;
        for (std::size_t i = 0; i < s.labs.size(); ++i) {
            // logit share: 1.4 (80 %) at 0.001, 4 per doubling, less air_weight per unit of |air error|.
            const double logit = 1.4 + 4.0 * std::log2(v / 0.001) + air_weight * (0.5 - std::abs(s.labs[i][0].in_limits));
            const bool named = latent[i] < 1.0 / (1.0 + std::exp(-logit));
            pt.draw_named.push_back(named ? 1 : 0);
            pt.named += named ? 1 : 0;
            ++pt.campaigns;
        }
        s.limit.tried.push_back(pt);
    }
    s.limit.value = 0.001;
    return s;
}

}  // namespace

TEST_CASE("planning: a limit that hangs on the air probe's calibration is flagged with the limit a probe calibrated to "
          "half its spec would reach and calibrations it does not hang on are not", "[planning][power]") {
    // As textile does in the bench's design (docs/notes/reconcile-history.md, tenth pass): labs whose air probe
    // erred by more than half its limit name it far less often.
    auto s = synthetic_plan(3, 6.0);
    rc::calibration_sensitivity(s.limit, s.labs, 0.8, 11);
    REQUIRE(s.limit.calibration.size() == 5);
    for (const auto& c : s.limit.calibration) {
        INFO(c.channel << " rho " << c.rank_correlation << " p " << c.p_value);
        CHECK(c.within + c.beyond == 40);
        CHECK(c.value == 0.001);
        CHECK(c.p_value > 0.0);
        CHECK(c.p_value <= 1.0);
        if (c.channel == "air_temp_c") {
            CHECK(c.flagged);
            CHECK(c.rank_correlation < -0.3);
            CHECK(static_cast<double>(c.within_named) / c.within > static_cast<double>(c.beyond_named) / c.beyond);
            // The labs within half the limit, counted here: the limit read from them alone lies in
            // the bracket where their own share crosses 80 %.
            std::vector<double> share;
            for (const auto& t : s.limit.tried) {
                int in = 0, named = 0;
                for (std::size_t i = 0; i < s.labs.size(); ++i)
                    if (std::abs(s.labs[i][0].in_limits) <= 0.5) ++in, named += t.draw_named[i];
                share.push_back(static_cast<double>(named) / in);
            }
            REQUIRE(c.limit_within);
            if (share[0] >= 0.8) {
                CHECK(c.limit_within_at_most);
                CHECK(*c.limit_within == 0.0008);
            } else {
                const auto up = std::find_if(share.begin(), share.end(), [](double x) { return x >= 0.8; }) - share.begin();
                REQUIRE(up > 0);
                REQUIRE(up < 3);
                CHECK(*c.limit_within >= s.limit.tried[static_cast<std::size_t>(up - 1)].value);
                CHECK(*c.limit_within <= s.limit.tried[static_cast<std::size_t>(up)].value);
            }
            CHECK(*c.limit_within <= *s.limit.value);
        } else {
            CHECK_FALSE(c.flagged);
        }
    }
    // The text says it, in the probe's own terms.
    rc::PowerReport plan;
    plan.campaign_replicates = 3;
    plan.replicates = {3};
    s.limit.replicates = 3;
    plan.limits = {s.limit};
    const std::string text = rc::power_to_text(plan);
    CHECK_THAT(text, Catch::Contains("textile_resistance: the air probe's calibration"));
    CHECK_THAT(text, Catch::Contains("With the air probe calibrated to ±0.1 °C: "));
    CHECK_THAT(text, Catch::Contains("within ±0.1 °C (half its limit)"));
    CHECK_THAT(text, !Catch::Contains("humidity probe's calibration"));
    const auto j = rc::power_to_json(plan);
    // A plan whose verdicts do not hang on the air error says so, in one line.
    auto none = synthetic_plan(4, 0.0);
    rc::calibration_sensitivity(none.limit, none.labs, 0.8, 11);
    for (const auto& c : none.limit.calibration) REQUIRE_FALSE(c.flagged);
    none.limit.replicates = 3;
    plan.limits = {none.limit};
    CHECK_THAT(rc::power_to_text(plan), Catch::Contains("Calibration: no limit here hangs on how far a probe"));
    REQUIRE(j["limits"][0]["calibration"].size() == 5);
    CHECK(j["limits"][0]["calibration"][0]["channel"] == "air_temp_c");
    CHECK(j["limits"][0]["calibration"][0]["flagged"] == true);
}

TEST_CASE("planning: where no calibration matters a term is flagged in at most 5 % of plans (plus the binomial margin)",
          "[planning][power][proof]") {
    // 200 plans whose verdicts are drawn independently of every lab's errors: a flag is false.
    int flagged = 0, p_low = 0, tests = 0;
    for (std::uint64_t seed = 1; seed <= 200; ++seed) {
        auto s = synthetic_plan(1000 + seed, 0.0);
        rc::calibration_sensitivity(s.limit, s.labs, 0.8, seed);
        bool any = false;
        for (const auto& c : s.limit.calibration) {
            any = any || c.flagged;
            p_low += c.p_value < 0.05 ? 1 : 0;
            ++tests;
        }
        flagged += any ? 1 : 0;
    }
    INFO(flagged << " of 200 plans flagged; " << p_low << " of " << tests << " p-values below 0.05");
    CHECK(flagged <= 20);             // P(Binomial(200, 0.05) > 20) < 0.01
    CHECK(p_low <= 72);               // 1000 tests at 5 %: mean 50, and 72 is 3.2 sd above
    CHECK(p_low >= 30);               // a test that never rejects would pass the first checks too
}

TEST_CASE("planning: a drawn lab's grids are the same whatever effect is concealed (its recorded conditions come from "
          "its seed alone) and reconcile given them reports what it reports with its own",
          "[planning][power][proof]") {
    // The planner makes each drawn lab's grids once and shares them across the values and terms
    // tried there: that changes no answer only if a lab's conditions do not depend on the effect.
    const auto model = recorded(15);
    rc::Options opt;
    opt.null_simulations = 400;
    const auto simulator = model->campaign_simulator(opt.instruments, 1.0);
    REQUIRE(simulator);
    const tw::Term gamma{"humidity_buoyancy", {{"gamma", 146.0}}, "", {}};
    const auto none = simulator->draw({}, 3, 99);
    const auto with = simulator->draw({gamma}, 3, 99);
    const auto library = ev::single_library(*none);
    const auto shared = std::make_shared<const std::vector<ev::Grid>>(ev::make_grids(*none, library, opt.grid_steps));
    const auto own = ev::make_grids(*with, ev::single_library(*with), opt.grid_steps);
    REQUIRE(own.size() == shared->size());
    for (std::size_t k = 0; k < own.size(); ++k) {
        CHECK(own[k].term.label() == (*shared)[k].term.label());
        CHECK(own[k].raw == (*shared)[k].raw);
        CHECK(own[k].valid == (*shared)[k].valid);
    }
    const rc::Report mine = rc::reconcile(*with, opt);
    rc::Options given = opt;
    given.grids = shared;
    const rc::Report theirs = rc::reconcile(*with, given);
    REQUIRE(mine.explanation);
    REQUIRE(theirs.explanation);
    CHECK(theirs.explanation->label == mine.explanation->label);
    CHECK(theirs.explanation->values == mine.explanation->values);
    CHECK(theirs.explanation->interval_lo == mine.explanation->interval_lo);
    CHECK(theirs.statement == mine.statement);
    // Grids of other candidates (another model's) are not used: reconcile makes its own.
    const auto other = recorded(16, 2);
    rc::Options wrong = opt;
    wrong.grids = std::make_shared<const std::vector<ev::Grid>>(ev::make_grids(*other, ev::single_library(*other), 12));
    CHECK(rc::reconcile(*with, wrong).statement == mine.statement);
}

TEST_CASE("planning: a prediction with a term scoped to some zones is the full prediction exactly (the other zones "
          "taken from the twin as given or from the thread's last prediction with the same other terms)",
          "[planning][power]") {
    // The forward model computes only the zones a region's wet fraction (or a zone's leak or gain)
    // touches and takes the rest from what it kept: the numbers must be those of every zone
    // computed, here a model whose own version holds the same terms (predicted in full).
    test::SyntheticOptions o;
    o.seed = 21;
    o.replicates = 3;
    const auto cases = test::make_campaign(tw::TwinVersion{"world", {}}, o);
    const auto model = rc::make_twin_model(cases, tw::TwinVersion{});
    auto full = [&](const std::vector<tw::Term>& terms) { return rc::make_twin_model(cases, tw::TwinVersion{"all", terms})->predict({}); };
    auto wet = [](double f) { return tw::Term{"partial_wettedness", {{"fraction", f}}, "head", {}}; };
    auto gamma = [](double g) { return tw::Term{"humidity_buoyancy", {{"gamma", g}}, "", {}}; };
    const tw::Term leak{"heat_leak", {{"q_w_m2", 7.0}}, "", {5, 23}};
    const tw::Term gain{"zone_gain", {{"gain", 0.03}}, "", {2}};
    // In the order a pair's scan and fit ask: the same global term again (kept), another, back.
    const std::vector<std::vector<tw::Term>> asked = {
        {wet(0.5)}, {gamma(100.0), wet(0.5)}, {gamma(100.0), wet(0.7)}, {gamma(120.0), wet(0.7)},
        {gamma(100.0), wet(0.9)}, {gamma(120.0), wet(0.2)}, {gamma(80.0), leak}, {leak, gain}, {wet(0.3), gain},
        {gamma(100.0)}, {gamma(100.0), wet(0.5)}};
    for (const auto& extra : asked) {
        INFO(extra.size() << " terms, the first " << extra.front().name);
        CHECK(model->predict(extra) == full(extra));
    }
}

TEST_CASE("planning: the plan is the same on one thread and on two (each drawn campaign from its own seed and its "
          "verdict gathered in order), its progress counts every drawn campaign reconciled once, and a lab's verdict its "
          "own verdicts bracket is implied: the plan with every lab reconciled, where none breaks the order",
          "[planning][power][proof]") {
    const auto model = recorded(17);
    rc::Options opt;
    // Sameness, not power: a small null and few drawn labs (46 s at 400 and 5 in the default
    // build, many minutes under the sanitizers).
    opt.null_simulations = 200;
    rc::PowerOptions po;
    po.campaigns = 3;
    po.terms = {"humidity_buoyancy"};
    std::vector<rc::PowerProgress> seen;
    po.progress = [&](const rc::PowerProgress& p) { seen.push_back(p); };  // one call at a time
    po.threads = 1;
    const auto one = rc::detection_limits(*model, opt, {3}, po);
    const auto calls_one = seen;
    seen.clear();
    po.threads = 2;
    const auto two = rc::detection_limits(*model, opt, {3}, po);
    REQUIRE(one.limits.size() == two.limits.size());
    int whole = 0;
    for (std::size_t i = 0; i < one.limits.size(); ++i) {
        const auto& a = one.limits[i];
        const auto& b = two.limits[i];
        CHECK(a.label == b.label);
        CHECK(a.method == b.method);
        CHECK(a.value == b.value);
        CHECK(a.simulated_power == b.simulated_power);
        REQUIRE(a.tried.size() == b.tried.size());
        for (std::size_t t = 0; t < a.tried.size(); ++t) {
            CHECK(a.tried[t].value == b.tried[t].value);
            CHECK(a.tried[t].draw_named == b.tried[t].draw_named);
            CHECK(a.tried[t].named_alone == b.tried[t].named_alone);
            CHECK(a.tried[t].reconciled == b.tried[t].reconciled);
            if (a.method == "whole decision") whole += a.tried[t].reconciled;  // the implied ones are not reconciled
        }
        REQUIRE(a.calibration.size() == b.calibration.size());
        for (std::size_t c = 0; c < a.calibration.size(); ++c) CHECK(a.calibration[c].p_value == b.calibration[c].p_value);
    }
    REQUIRE(whole > 0);
    for (const std::vector<rc::PowerProgress>* calls : {&calls_one, static_cast<const std::vector<rc::PowerProgress>*>(&seen)}) {
        REQUIRE(static_cast<int>(calls->size()) == whole);
        for (std::size_t i = 0; i < calls->size(); ++i) {
            CHECK((*calls)[i].campaigns_done == static_cast<int>(i) + 1);
            CHECK((*calls)[i].campaigns_expected >= (*calls)[i].campaigns_done);
            CHECK((*calls)[i].terms == 1);
            CHECK((*calls)[i].label == "humidity_buoyancy");
        }
    }
    // A lab's verdict its own verdicts at other values bracket is implied, not reconciled: with
    // every lab reconciled at every value (--power-every-lab) and none breaking the order, the plan
    // is the same lab by lab, with fewer reconciles.
    po.every_lab = true;
    po.progress = nullptr;
    const auto every = rc::detection_limits(*model, opt, {3}, po);
    REQUIRE(every.limits.size() == two.limits.size());
    int implied_tests = 0;
    for (std::size_t i = 0; i < two.limits.size(); ++i) {
        const auto& a = every.limits[i];
        const auto& b = two.limits[i];
        if (a.method != "whole decision") continue;
        ++implied_tests;
        REQUIRE(a.tried.size() >= 2);  // a walk: the implied verdicts need a second value
        REQUIRE(a.non_monotone_labs.has_value());
        REQUIRE(*a.non_monotone_labs == 0);  // this design's labs name gamma more as it grows
        CHECK_FALSE(b.non_monotone_labs.has_value());
        REQUIRE(a.tried.size() == b.tried.size());
        int reconciled_every = 0, reconciled_implied = 0;
        for (std::size_t t = 0; t < a.tried.size(); ++t) {
            CHECK(a.tried[t].reconciled == a.tried[t].campaigns);
            CHECK(a.tried[t].value == b.tried[t].value);
            CHECK(a.tried[t].draw_named == b.tried[t].draw_named);
            reconciled_every += a.tried[t].reconciled;
            reconciled_implied += b.tried[t].reconciled;
        }
        CHECK(a.value == b.value);
        CHECK(reconciled_implied < reconciled_every);
        CHECK(reconciled_implied >= po.campaigns);  // the first value: every lab
    }
    CHECK(implied_tests == 1);
}
