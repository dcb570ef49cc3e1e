// The planner's campaigns (`--power`, docs/reconcile.md "Detection limits"): a campaign of the
// same design drawn anew from what the recorded one estimated, with an effect concealed. The
// planner runs reconcile itself on these, so they must be campaigns reconcile can read as it reads
// a recording: the same cases and zones, the asked-for replicates, the recorded scatter's size,
// and reproducible from their seed.
#include <catch2/catch.hpp>

#include <cmath>

#include "tests/reconcile/synthetic_campaign.hpp"

using namespace manikind;
namespace rc = manikind::analysis::reconcile;
namespace tw = manikind::physics::twin;

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
          "none is claimed without one", "[reconcile][power]") {
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
          "[reconcile][power]") {
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
          "unexplained, never that the twin agrees", "[reconcile][power]") {
    // Found by the planner: a small humidity buoyancy shows at the isothermal cases' kink as many
    // zones' offsets, no single term passing. The statement fell through to "The twin agrees with
    // the recordings within their noise" while quoting an evidence beyond the null.
    const auto model = recorded(12);
    rc::Options opt;
    opt.null_simulations = 400;
    const tw::Term gamma{"humidity_buoyancy", {{"gamma", 30.0}}, "", {}};
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
