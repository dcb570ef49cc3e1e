// Detection limits for planning (docs/reconcile.md, "Detection limits"): the smallest effect of
// each candidate that reconcile names with 80 % power, for this campaign's cases and noise and
// for other numbers of replicates (the random part of the noise scales as 1/replicates; the
// systematic parts do not).
#include <algorithm>
#include <atomic>
#include <cmath>
#include <exception>
#include <functional>
#include <map>
#include <mutex>
#include <numeric>
#include <optional>
#include <random>
#include <set>
#include <thread>

#include <fmt/format.h>

#include <boost/math/distributions/non_central_chi_squared.hpp>

#include "analysis/reconcile/evidence.hpp"
#include "analysis/reconcile/reconcile.hpp"

namespace manikind::analysis::reconcile {
namespace ev = evidence;
namespace {

constexpr int kGridSteps = 120;

// The share of a value's campaigns that named the term.
double share(const PowerPoint& t) { return t.campaigns > 0 ? static_cast<double>(t.named) / t.campaigns : 0.0; }

// The value the plan reports its share at: the first tried at or beyond the limit (none: no limit).
const PowerPoint* at_limit(const DetectionLimit& d) {
    if (!d.value) return nullptr;
    for (const auto& t : d.tried)
        if (std::abs(t.value - d.null_value) >= std::abs(*d.value - d.null_value) - 1e-12) return &t;
    return nullptr;
}
constexpr int kPowerSimulations = 400;

// The whitened prediction at a parameter value between grid points (linear interpolation).
Eigen::VectorXd at(const ev::WhitenedGrid& g, double theta) {
    const auto& t = g.grid->theta;
    const double step = t[1] - t[0];
    const double x = std::clamp((theta - t.front()) / step, 0.0, static_cast<double>(t.size() - 1));
    const auto i = std::min(static_cast<Eigen::Index>(x), static_cast<Eigen::Index>(t.size()) - 2);
    const double f = x - static_cast<double>(i);
    return (1.0 - f) * g.w.col(i) + f * g.w.col(i + 1);
}

// The bracket around `power` the limit is read from: the index of its upper value, the last value
// tried that was named often enough right after one named too rarely (values sorted by |effect|:
// the bracket farthest from no effect). None when there is no such pair.
std::optional<std::size_t> upper_bracket(const std::vector<PowerPoint>& tried, double power) {
    for (std::size_t i = tried.size(); i-- > 1;)
        if (tried[i - 1].named < power * tried[i - 1].campaigns && tried[i].named >= power * tried[i].campaigns) return i;
    return std::nullopt;
}

// Where the power curve crosses `power` (returns log|effect - null|): in the bracket, linear in
// logit(share) against log|effect| (a half campaign added each way keeps the logit finite at 0 or
// all). Values sorted by |effect|.
double power_crossing(const std::vector<PowerPoint>& tried, double null_value, double power) {
    auto x = [&](const PowerPoint& t) { return std::log(std::abs(t.value - null_value)); };
    auto logit = [](const PowerPoint& t) {
        const double p = (t.named + 0.5) / (t.campaigns + 1.0);
        return std::log(p / (1.0 - p));
    };
    const double target = std::log(power / (1.0 - power));
    const auto i = upper_bracket(tried, power);
    if (!i) return x(tried.back());
    const auto& lo = tried[*i - 1];
    const auto& hi = tried[*i];
    const double ya = logit(lo), yb = logit(hi);
    const double f = yb > ya ? std::clamp((target - ya) / (yb - ya), 0.0, 1.0) : 1.0;
    return x(lo) + f * (x(hi) - x(lo));
}

// The limit read from values tried (sorted by |effect|): the 80 % crossing between the values that
// bracket it; the smallest value tried when that is already named often enough (`at_most`); none
// when no value tried was.
struct ReadLimit {
    std::optional<double> value;
    bool at_most = false;
};
ReadLimit read_limit(const std::vector<PowerPoint>& tried, double null_value, double far, double power) {
    if (tried.empty()) return {};
    if (share(tried.front()) < power && share(tried.back()) >= power)
        return {null_value + (far > null_value ? 1.0 : -1.0) * std::exp(power_crossing(tried, null_value, power)), false};
    if (share(tried.front()) >= power) return {tried.front().value, true};
    return {};
}

// Mid-ranks (ties share their mean rank), for a rank correlation with many tied counts.
std::vector<double> mid_ranks(const std::vector<double>& v) {
    std::vector<std::size_t> order(v.size());
    std::iota(order.begin(), order.end(), 0);
    std::sort(order.begin(), order.end(), [&](auto a, auto b) { return v[a] < v[b]; });
    std::vector<double> r(v.size());
    for (std::size_t i = 0; i < order.size();) {
        std::size_t j = i;
        while (j + 1 < order.size() && v[order[j + 1]] == v[order[i]]) ++j;
        for (std::size_t k = i; k <= j; ++k) r[order[k]] = 0.5 * static_cast<double>(i + j);
        i = j + 1;
    }
    return r;
}

}  // namespace

// How the limit of `d` hangs on each calibration its drawn labs erred in (the same labs at every
// value tried: common random numbers). Each lab's count of values tried at which it named the term
// against |its error|: Spearman's rho, with a one-sided permutation p (does a larger error hide the
// term?), flagged at 5 % over the calibrations tested for this term (Bonferroni). The labs whose
// error lies within half its limit are the labs of a calibration twice as tight (exactly so for a
// rectangular spec): the limit read from them alone is what that calibration would buy.
void calibration_sensitivity(DetectionLimit& d, const std::vector<std::vector<DrawnCalibrationError>>& labs, double power,
                             std::uint64_t seed) {
    d.calibration.clear();
    const std::size_t n = labs.size();
    if (n < 4 || d.tried.empty()) return;
    const double far = d.tried.back().value;  // which side of "no effect" the values lie on
    for (const auto& t : d.tried)
        if (t.draw_named.size() != n) return;
    std::vector<double> count(n, 0.0);
    for (const auto& t : d.tried)
        for (std::size_t i = 0; i < n; ++i) count[i] += t.draw_named[i] ? 1.0 : 0.0;
    // The counts are taken where the report's share is (the largest value tried when no limit).
    const PowerPoint* at = at_limit(d);
    if (!at) at = &d.tried.back();
    const std::vector<double> rc = mid_ranks(count);
    const double mean_rank = 0.5 * static_cast<double>(n - 1);
    double ss_c = 0.0;
    for (double r : rc) ss_c += (r - mean_rank) * (r - mean_rank);
    std::vector<std::string> channels;
    for (const auto& e : labs.front()) channels.push_back(e.channel);
    for (const auto& channel : channels) {
        CalibrationSensitivity c;
        c.channel = channel;
        c.value = at->value;
        std::vector<double> size(n, 0.0);
        bool complete = true;
        for (std::size_t i = 0; i < n && complete; ++i) {
            const auto it = std::find_if(labs[i].begin(), labs[i].end(), [&](const auto& e) { return e.channel == channel; });
            complete = it != labs[i].end();
            if (complete) {
                size[i] = std::abs(it->in_limits);
                c.limit = it->limit;
            }
        }
        if (!complete) continue;
        const std::vector<double> rs = mid_ranks(size);
        double ss_s = 0.0;
        for (double r : rs) ss_s += (r - mean_rank) * (r - mean_rank);
        auto dot = [&](const std::vector<double>& a, const std::vector<double>& b) {
            double s = 0.0;
            for (std::size_t i = 0; i < n; ++i) s += (a[i] - mean_rank) * (b[i] - mean_rank);
            return s;
        };
        const double observed = dot(rs, rc);
        if (ss_s > 0.0 && ss_c > 0.0) {
            c.rank_correlation = observed / std::sqrt(ss_s * ss_c);
            constexpr int kPermutations = 20000;
            std::mt19937_64 rng(seed);
            std::vector<double> perm = rc;
            int as_low = 0;
            for (int b = 0; b < kPermutations; ++b) {
                std::shuffle(perm.begin(), perm.end(), rng);
                as_low += dot(rs, perm) <= observed + 1e-9 ? 1 : 0;
            }
            c.p_value = (as_low + 1.0) / (kPermutations + 1.0);
        }
        // The labs within half the limit and beyond, at the reported value and over every value tried.
        std::vector<PowerPoint> within;
        for (const auto& t : d.tried) {
            PowerPoint w;
            w.value = t.value;
            for (std::size_t i = 0; i < n; ++i) {
                const bool in = size[i] <= 0.5;
                if (in) {
                    ++w.campaigns;
                    w.named += t.draw_named[i] ? 1 : 0;
                }
                if (&t == at) {
                    (in ? c.within : c.beyond) += 1;
                    (in ? c.within_named : c.beyond_named) += t.draw_named[i] ? 1 : 0;
                }
            }
            within.push_back(std::move(w));
        }
        if (c.within > 0) {
            const ReadLimit r = read_limit(within, d.null_value, far, power);
            c.limit_within = r.value;
            c.limit_within_at_most = r.at_most;
        }
        d.calibration.push_back(std::move(c));
        seed += 1;
    }
    for (auto& c : d.calibration) c.flagged = c.p_value < 0.05 / static_cast<double>(d.calibration.size());
}

std::optional<double> coarse_bracket_middle(const std::vector<PowerPoint>& tried, double null_value, double power) {
    const auto i = upper_bracket(tried, power);  // the bracket power_crossing reads
    if (!i) return std::nullopt;
    const auto& lo = tried[*i - 1];
    const auto& hi = tried[*i];
    const bool coarse = share(hi) - share(lo) > 0.25 || hi.named == hi.campaigns;
    if (!coarse) return std::nullopt;
    return null_value + (hi.value > null_value ? 1.0 : -1.0) * std::sqrt(std::abs(lo.value - null_value) * std::abs(hi.value - null_value));
}

PowerReport detection_limits(const ForwardModel& model, const Options& opt, const std::vector<int>& replicates,
                             const PowerOptions& po) {
    const double power = po.power;
    const int campaigns = po.campaigns;
    const int threads = std::max(1, std::min(campaigns, po.threads > 0 ? po.threads : static_cast<int>(std::thread::hardware_concurrency())));
    // Campaigns of this design drawn anew (none without replicate scatter). A lab's probes: each
    // off by one calibration error, the same in every case (shared fraction 1). The noise model's
    // 0.5 is a cautious covariance for the claims; drawn per case, errors at the isothermal cases'
    // kink sank gamma and the air bias, and a half-shared wall error hid a wall offset's dilution.
    const std::unique_ptr<CampaignSimulator> simulator = campaigns > 0 ? model.campaign_simulator(opt.instruments, 1.0) : nullptr;
    const bool whole = simulator != nullptr;
    const auto& pts = model.points();
    PowerReport rep;
    rep.alpha = opt.alpha;
    const NoiseModel noise = model.noise_model(opt.instruments, opt.probe_shared_fraction);
    rep.campaign_replicates = noise.point_replicates.empty() ? 0 : *std::max_element(noise.point_replicates.begin(), noise.point_replicates.end());
    rep.replicates = replicates;
    if (rep.campaign_replicates > 0 &&
        std::find(replicates.begin(), replicates.end(), rep.campaign_replicates) == replicates.end())
        rep.replicates.push_back(rep.campaign_replicates);
    std::sort(rep.replicates.begin(), rep.replicates.end());
    rep.replicates.erase(std::unique(rep.replicates.begin(), rep.replicates.end()), rep.replicates.end());
    const std::unique_ptr<NoiseResampler> resampler = model.noise_resampler(opt.instruments, opt.probe_shared_fraction);
    const auto base = model.predict({});
    // Every candidate stays in the family: the claim threshold and the rivals are reconcile's own
    // whichever candidates are planned (a family of only those planned had a lower threshold, so
    // `--power-terms` printed limits reconcile would not reach). `planned` picks the limits computed.
    const std::vector<CandidateTerm> library = ev::single_library(model, opt.hypotheses);
    // By default the named terms are planned; a generated hypothesis (input_pattern) only when
    // `--power-terms` names it: it stays in the family (the threshold) either way, and planning
    // every generated one would double the plan's time (issue 61, part 6).
    std::vector<bool> planned(library.size(), false);
    if (po.terms.empty())
        for (std::size_t k = 0; k < library.size(); ++k) planned[k] = !library[k].generated();
    for (const auto& name : po.terms) {
        bool found = false;
        for (std::size_t k = 0; k < library.size(); ++k)
            if (library[k].label() == name || library[k].term == name) planned[k] = found = true;
        if (!found) {
            std::string known;
            for (const auto& c : library) known += (known.empty() ? "" : ", ") + c.label();
            throw std::invalid_argument("no candidate '" + name + "' for this campaign (candidates: " + known + ")");
        }
    }
    const std::vector<ev::Grid> grids = ev::make_grids(model, library, kGridSteps);
    std::vector<std::size_t> idx(pts.size());
    std::iota(idx.begin(), idx.end(), 0);
    std::mt19937_64 rng(opt.seed + 7);
    // How far the whole decision moved each candidate's limit from the fast model's, at this
    // campaign's replicates (checked first); the other replicate counts are scaled by it.
    std::map<std::string, double> whole_scale;
    struct Planned {
        DetectionLimit d;
        std::size_t k = 0;                  // in library
        double far = 0.0;                   // the bound on the side the values walk to
        std::optional<double> fast;         // the fast model's limit, where the walk starts
    };
    // The whole decision (reconcile itself) on campaigns of this design drawn anew with the effect
    // concealed, the same draws at every value tried (common random numbers). Each term walks its
    // own values (below); the terms walk together in rounds: in a round every term not yet settled
    // tries its next value, and each drawn lab is reconciled at all of them, its grids made once
    // for the round (a lab's recorded conditions come from its seed alone, whatever is concealed:
    // the same grids at every value and term). The drawn labs are shared out over `threads`; each
    // verdict is kept in its lab's place, so the answer does not depend on the thread count.
    auto whole_decision = [&](std::vector<Planned>& terms, int n, double threshold) {
        struct Walk {
            Planned* t = nullptr;
            std::vector<std::vector<DrawnCalibrationError>> labs;  // each drawn lab's, from its first draw
            int stage = 0;                  // 0: the fast value next; 1: stepping out; 2: the bracket's middle; 3: done
            int steps = 0;
            bool up = false;
            double theta = 0.0;
            bool settled = false;
        };
        std::vector<Walk> walks;
        for (auto& t : terms)
            if (t.fast) {
                Walk w;
                w.t = &t;
                w.labs.resize(static_cast<std::size_t>(campaigns));
                walks.push_back(std::move(w));
            }
        auto by_effect = [](DetectionLimit& d) {
            std::sort(d.tried.begin(), d.tried.end(),
                      [&](const auto& a, const auto& b) { return std::abs(a.value - d.null_value) < std::abs(b.value - d.null_value); });
        };
        // The next value a term tries, none once it is settled: steps of 25 % of the effect from the
        // fast model's value until the 80 % share is bracketed (a value named less often and one
        // named at least that often). A bracket that climbs steeply (more than a quarter of the
        // campaigns between its ends, or its upper end named in all) is read coarsely by a line
        // through its ends: the wall's 27/40 at 1.125 °C and 40/40 at 1.406 °C read 1.17 °C, where
        // the generator's campaigns named 26 of 40 at 1.19 °C. Its geometric middle is tried once
        // before the curve is read (docs/notes/reconcile-history.md, fifth pass).
        auto next_value = [&](Walk& w) -> std::optional<double> {
            DetectionLimit& d = w.t->d;
            const auto& p = library[w.t->k].parameters[0];
            constexpr double kStep = 1.25;
            if (w.stage == 0) {
                w.stage = 1;
                w.theta = *w.t->fast;
                return w.theta;
            }
            if (w.stage == 1) {
                if (w.steps == 0) w.up = share(d.tried.front()) < power;
                const bool below = std::any_of(d.tried.begin(), d.tried.end(), [&](const auto& t) { return share(t) < power; });
                const bool above = std::any_of(d.tried.begin(), d.tried.end(), [&](const auto& t) { return share(t) >= power; });
                const double next = p.null_value + (w.theta - p.null_value) * (w.up ? kStep : 1.0 / kStep);
                if (w.steps < 10 && !(below && above) && (w.t->far - next) * (w.t->far - p.null_value) >= 0.0) {
                    ++w.steps;
                    w.theta = next;
                    return next;
                }
                w.stage = 2;
            }
            if (w.stage == 2) {
                w.stage = 3;
                by_effect(d);
                const bool bracketed = share(d.tried.front()) < power && share(d.tried.back()) >= power;
                if (const auto mid = bracketed ? coarse_bracket_middle(d.tried, p.null_value, power) : std::nullopt) return *mid;
            }
            return std::nullopt;
        };
        // Progress: drawn campaigns reconciled, against the values tried so far and, for each term
        // not settled, the mean count the settled ones took (4 before any has).
        PowerProgress progress;
        progress.terms = static_cast<int>(walks.size());
        progress.replicates = n;
        std::mutex progress_mutex;
        // A term's first value reconciles every lab; a later one only the labs their own verdicts do
        // not bracket (every_lab: all), counted at the share seen so far at later values (half before).
        auto expect = [&] {
            int settled_values = 0, settled = 0, later_values = 0, later_reconciled = 0;
            for (const auto& w : walks) {
                if (w.settled) settled_values += static_cast<int>(w.t->d.tried.size()), ++settled;
                for (std::size_t v = 1; v < w.t->d.tried.size(); ++v) ++later_values, later_reconciled += w.t->d.tried[v].reconciled;
            }
            const double per_term = settled > 0 ? static_cast<double>(settled_values) / settled : 4.0;
            const double later_share = po.every_lab ? 1.0 : later_values > 0 ? later_reconciled / (double(later_values) * campaigns) : 0.5;
            double expected = 0.0;
            for (const auto& w : walks) {
                for (const auto& pt : w.t->d.tried) expected += pt.reconciled;
                if (w.settled) continue;
                const double tried = static_cast<double>(w.t->d.tried.size());
                const double more = std::max(per_term, tried + 1.0) - tried;  // values still to try
                expected += campaigns * (tried == 0.0 ? 1.0 + (more - 1.0) * later_share : more * later_share);
            }
            progress.terms_done = settled;
            progress.campaigns_expected = std::max(progress.campaigns_done, static_cast<int>(std::lround(expected)));
        };
        auto settle_walk = [&](Walk& w) {
            DetectionLimit& d = w.t->d;
            const auto& p = library[w.t->k].parameters[0];
            by_effect(d);
            // The power curve read at 80 % between the values that bracket it (interpolated,
            // where a pass/fail ladder would keep the luckiest value).
            d.value = read_limit(d.tried, p.null_value, w.t->far, power).value;
            int total = 0;
            for (const auto& t : d.tried) total += t.campaigns;
            d.campaigns = total;
            // Reported: the share named at the first value tried at or beyond the limit.
            const PowerPoint* reported = at_limit(d);
            d.simulated_power = reported ? share(*reported) : 0.0;
            d.method = "whole decision";
            if (po.every_lab) {
                // Labs that named the term at a value and missed it at a larger one (d.tried is by
                // effect): what the implied verdicts of the default assume away.
                int non_monotone = 0;
                for (int i = 0; i < campaigns; ++i) {
                    bool named_nearer = false, broken = false;
                    for (const auto& pt : d.tried) {
                        const bool named = pt.draw_named[static_cast<std::size_t>(i)] != 0;
                        broken = broken || (named_nearer && !named);
                        named_nearer = named_nearer || named;
                    }
                    non_monotone += broken ? 1 : 0;
                }
                d.non_monotone_labs = non_monotone;
            }
            calibration_sensitivity(d, w.labs, power, opt.seed + 104729u * (w.t->k + 1));
            whole_scale[d.label] = d.value ? (*d.value - p.null_value) / (*w.t->fast - p.null_value) : 0.0;
            w.settled = true;
        };
        Options o = opt;
        o.null_threshold = threshold;
        for (;;) {
            struct Job {
                Walk* w;
                double theta;
                std::vector<physics::twin::Term> truth;
            };
            std::vector<Job> jobs;
            for (auto& w : walks) {
                if (w.settled) continue;
                if (const auto v = next_value(w))
                    jobs.push_back({&w, *v, to_twin_terms({library[w.t->k]}, {*v})});
                else
                    settle_walk(w);
            }
            {
                const std::lock_guard lock(progress_mutex);
                expect();
            }
            if (jobs.empty()) break;
            // reconcile's own grid (opt.grid_steps): on a coarser one a term whose "no effect" is
            // the grid's end (the head's wet fraction 1, h0 0, textile 0) lost its evidence between
            // the end and the next step, where the parabola cannot refine (40 steps: 5 of 20 named
            // at fraction 0.9875, 19 of 20 at 0.988 on reconcile's 120).
            // Pairs are tried, as reconcile tries them: a drawn lab's probe error can show beside a
            // concealed effect (the air bias beside the textile term), and the pair that names both
            // is a true answer (names_concealed). Counting only the term alone, without pairs, the
            // textile term never reached 80 % planning from the bench's labs 78 and 80
            // (docs/notes/reconcile-history.md, fourth pass).
            std::vector<std::vector<char>> hit(jobs.size(), std::vector<char>(static_cast<std::size_t>(campaigns), 0));
            std::vector<std::vector<char>> alone = hit, ran = hit;
            // A lab's verdict at theta implied by its own at the values this term tried before: named
            // at a smaller effect, named here; missed at a larger one, missed here (PowerOptions::every_lab).
            auto implied = [&](const Job& job, std::size_t lab) -> std::optional<std::pair<char, char>> {
                if (po.every_lab) return std::nullopt;
                const DetectionLimit& d = job.w->t->d;
                const double here = std::abs(job.theta - d.null_value);
                for (const auto& pt : d.tried) {
                    const double there = std::abs(pt.value - d.null_value);
                    if (pt.draw_named[lab] && there <= here) return std::pair<char, char>{1, pt.draw_alone[lab]};
                    if (!pt.draw_named[lab] && there >= here) return std::pair<char, char>{0, 0};
                }
                return std::nullopt;
            };
            std::atomic<int> next{0};
            std::exception_ptr failed;
            auto work = [&] {
                try {
                    for (int i = next++; i < campaigns; i = next++) {
                        const auto at_i = static_cast<std::size_t>(i);
                        std::shared_ptr<const std::vector<ev::Grid>> lab_grids;
                        for (std::size_t j = 0; j < jobs.size(); ++j) {
                            if (const auto verdict = implied(jobs[j], at_i)) {
                                hit[j][at_i] = verdict->first;
                                alone[j][at_i] = verdict->second;
                                continue;
                            }
                            ran[j][at_i] = 1;
                            std::vector<physics::twin::Term> calibration;
                            auto& lab = jobs[j].w->labs[at_i];
                            const auto sim = simulator->draw(jobs[j].truth, n, opt.seed + 7919u * static_cast<std::uint64_t>(i + 1),
                                                             &calibration, lab.empty() ? &lab : nullptr);
                            if (!lab_grids)
                                lab_grids = std::make_shared<const std::vector<ev::Grid>>(
                                    ev::make_grids(*sim, ev::single_library(*sim, opt.hypotheses), std::max(12, opt.grid_steps)));
                            Options mine = o;
                            mine.grids = lab_grids;
                            // Only the verdict is counted: reconcile may stop once it is settled.
                            mine.verdict_for = Options::VerdictFor{jobs[j].w->t->d.label, calibration};
                            const Report r = reconcile(*sim, mine);
                            const bool named = names_concealed(r, jobs[j].w->t->d.label, calibration);
                            hit[j][at_i] = named ? 1 : 0;
                            alone[j][at_i] = named && r.explanation->terms.size() == 1 ? 1 : 0;
                            const std::lock_guard lock(progress_mutex);
                            ++progress.campaigns_done;
                            progress.label = jobs[j].w->t->d.label;
                            if (po.progress) po.progress(progress);
                        }
                    }
                } catch (...) {
                    const std::lock_guard lock(progress_mutex);
                    if (!failed) failed = std::current_exception();
                    next = campaigns;  // the others stop at their next lab
                }
            };
            std::vector<std::thread> pool;
            for (int t = 1; t < threads; ++t) pool.emplace_back(work);
            work();
            for (auto& t : pool) t.join();
            if (failed) std::rethrow_exception(failed);
            for (std::size_t j = 0; j < jobs.size(); ++j) {
                PowerPoint pt;
                pt.value = jobs[j].theta;
                for (int i = 0; i < campaigns; ++i) {
                    const auto at_i = static_cast<std::size_t>(i);
                    pt.named += hit[j][at_i];
                    pt.named_alone += alone[j][at_i];
                    pt.draw_named.push_back(hit[j][at_i]);
                    pt.draw_alone.push_back(alone[j][at_i]);
                    pt.reconciled += ran[j][at_i];
                    ++pt.campaigns;
                }
                jobs[j].w->t->d.tried.push_back(std::move(pt));
            }
        }
    };
    std::vector<int> order = rep.replicates;
    std::stable_partition(order.begin(), order.end(), [&](int n) { return n == rep.campaign_replicates; });
    for (int n : order) {
        // The random part of the case means scales as (campaign's replicates) / n.
        Eigen::MatrixXd cov = noise.covariance - noise.random_covariance;
        for (Eigen::Index a = 0; a < cov.rows(); ++a)
            for (Eigen::Index b = 0; b < cov.cols(); ++b)
                cov(a, b) += noise.random_covariance(a, b) * noise.point_replicates[static_cast<std::size_t>(a)] / n;
        const ev::Subset s = ev::make_subset(model, cov, idx, base, &noise.shared_factor);
        std::vector<ev::WhitenedGrid> wg(grids.size());
        for (std::size_t k = 0; k < grids.size(); ++k) wg[k] = ev::whiten_grid(s, grids[k]);
        std::vector<const ev::WhitenedGrid*> all;
        for (const auto& g : wg) all.push_back(&g);
        // The claim threshold reconcile would use with n replicates: the family (terms and each
        // zone's offset and gain) under one alpha, the noise model's own estimate re-drawn as it
        // would scatter with n replicates (docs/reconcile.md, "The null").
        const Eigen::MatrixXd local = model.supports("heat_leak") ? ev::local_directions(model, s, base, nullptr) : Eigen::MatrixXd();
        std::function<Eigen::MatrixXd(std::uint64_t)> draw;
        if (resampler) draw = [&](std::uint64_t seed) { return resampler->draw(seed, n); };
        const double threshold =
            ev::upper_quantile(ev::family_null(s, wg, local, draw, opt.null_simulations, opt.seed).max_evidence, opt.alpha);
        rep.claim_threshold[n] = threshold;

        std::vector<Planned> planned_here;  // the limits at n, in library order
        for (std::size_t k = 0; k < library.size(); ++k) {
            if (!planned[k]) continue;
            const auto& p = library[k].parameters[0];
            DetectionLimit d;
            d.label = library[k].label();
            d.parameter = p.name;
            d.unit = p.unit;
            d.null_value = p.null_value;
            d.replicates = n;
            // Walk away from "no effect" toward the side theory (or the upper bound) lies on.
            const double target = p.theory ? *p.theory : (p.null_value < p.hi ? p.hi : p.lo);
            const double far = target >= p.null_value ? p.hi : p.lo;
            // Noncentral chi2_1 approximation of the evidence: the first value with enough power.
            auto approx_power = [&](double theta) {
                const double lambda = (at(wg[k], theta) - s.w_base).squaredNorm();
                return boost::math::cdf(boost::math::complement(boost::math::non_central_chi_squared(1.0, std::max(lambda, 1e-12)), threshold));
            };
            const int steps = 400;
            std::optional<double> first;
            for (int i = 1; i <= steps && !first; ++i) {
                const double theta = p.null_value + (far - p.null_value) * i / steps;
                if (approx_power(theta) >= power) first = theta;
            }
            // Checked by simulation: the right term named (largest evidence, beyond the null).
            auto simulated_power = [&](double theta) {
                const Eigen::MatrixXd sim = ev::simulate(at(wg[k], theta), kPowerSimulations, rng);
                const Eigen::MatrixXd prof = ev::profile_chi2(all, sim);
                int named = 0;
                for (Eigen::Index b = 0; b < sim.cols(); ++b) {
                    Eigen::Index best = 0;
                    prof.col(b).minCoeff(&best);
                    const double evidence = (sim.col(b) - s.w_base).squaredNorm() - prof(best, b);
                    // A zone's offset or gain that explains more would be reported instead.
                    const double local_best = local.cols() > 0 ? ev::linear_evidence(local, sim.col(b) - s.w_base).maxCoeff() : 0.0;
                    named += evidence > threshold && evidence > local_best && static_cast<std::size_t>(best) == k ? 1 : 0;
                }
                return static_cast<double>(named) / kPowerSimulations;
            };
            // The fast model's limit: its first value, stepped out until its own simulation agrees.
            std::optional<double> fast;
            double fast_power = 0.0;
            if (first) {
                double theta = *first;
                fast_power = simulated_power(theta);
                for (int i = 0; i < 12 && fast_power < power; ++i) {
                    const double next = theta + (theta - p.null_value) * 0.25;
                    if ((far - next) * (far - p.null_value) < 0.0) break;
                    theta = next;
                    fast_power = simulated_power(theta);
                }
                if (fast_power >= power) fast = theta;
            }
            d.simulated_power = fast_power;
            d.method = "fast model";
            d.value = fast;
            planned_here.push_back({std::move(d), k, far, fast});
        }
        if (whole && n == rep.campaign_replicates) whole_decision(planned_here, n, threshold);
        for (auto& t : planned_here) rep.limits.push_back(std::move(t.d));
    }
    std::stable_sort(rep.limits.begin(), rep.limits.end(), [](const auto& a, const auto& b) { return a.replicates < b.replicates; });
    for (auto& d : rep.limits) {
        const auto it = whole_scale.find(d.label);
        if (d.replicates == rep.campaign_replicates || it == whole_scale.end() || !d.value) continue;
        const double v = d.null_value + (*d.value - d.null_value) * it->second;
        const auto spec = std::find_if(library.begin(), library.end(), [&](const auto& c) { return c.label() == d.label; });
        const auto& p = spec->parameters[0];
        d.value = it->second > 0.0 && v >= p.lo && v <= p.hi ? std::optional<double>(v) : std::nullopt;
        d.method = "scaled";
    }
    // Monotone in replicates by construction: a lab with more replicates can always analyse fewer,
    // so a limit reached with n' replicates is reached with any n > n'.
    for (auto& d : rep.limits) {
        for (const auto& e : rep.limits) {
            if (e.label != d.label || e.replicates >= d.replicates || !e.value) continue;
            if (!d.value || std::abs(*e.value - d.null_value) < std::abs(*d.value - d.null_value)) {
                d.value = e.value;
                d.simulated_power = std::max(d.simulated_power, e.simulated_power);
                // Said as what it is: the limit reached with fewer replicates, not this method's own.
                d.method = fmt::format("as at {} replicates", e.replicates);
            }
        }
    }
    return rep;
}

}  // namespace manikind::analysis::reconcile
