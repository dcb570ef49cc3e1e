// The forward models reconcile fits: the twin over recorded cases (with its noise model built
// from the replicates and the instruments' specs), and the whole-body h of the paper's CFD table.
#include <algorithm>
#include <array>
#include <atomic>
#include <cmath>
#include <limits>
#include <random>
#include <stdexcept>

#include <fmt/core.h>

#include "analysis/reconcile/noise_model.hpp"
#include "analysis/reconcile/forward_model.hpp"
#include "physics/psychrometrics.hpp"

namespace manikind::analysis::reconcile {
namespace tw = physics::twin;
namespace {

double spec_u(const Instruments& instruments, const std::string& channel, double reading) {
    const auto it = instruments.find(channel);
    return it == instruments.end() ? 0.0 : it->second.standard_uncertainty(reading);
}

// The half-width of a channel's limit at this reading (0 where the campaign gives no spec).
double spec_limit(const Instruments& instruments, const std::string& channel, double reading) {
    const auto it = instruments.find(channel);
    return it == instruments.end() ? 0.0 : it->second.limit(reading);
}

class TwinModel final : public ForwardModel {
public:
    TwinModel(std::vector<CaseInput> cases, tw::TwinVersion base) : cases_(std::move(cases)), base_(std::move(base)) {
        bool facing_known = false;
        for (const auto& in : cases_)
            for (const auto& zi : in.conditions.zones) facing_known = facing_known || zi.facing != 0;
        for (std::size_t c = 0; c < cases_.size(); ++c) {
            const CaseInput& in = cases_[c];
            const auto& cond = in.conditions;
            const double p_air = physics::vapour_pressure_pa(cond.air_temp_c, cond.air_rh_pct);
            const double c_air = physics::vapour_concentration_kg_m3(p_air, cond.air_temp_c);
            for (std::size_t z = 0; z < cond.zones.size(); ++z) {
                const double q = in.q_exp_w_m2.at(z);
                const double u = in.expanded_u_w_m2.at(z);
                if (!std::isfinite(q) || !std::isfinite(u) || u <= 0.0) continue;
                if (still_drifting(in, z)) continue;
                Point p;
                p.case_id = in.case_id;
                p.zone = cond.zones[z].zone;
                p.zone_name = z < in.zone_names.size() ? in.zone_names[z] : std::to_string(p.zone);
                p.region = cond.zones[z].region;
                p.q_exp = q;
                p.expanded_u = u;
                p.coverage_k = z < in.coverage_k.size() && in.coverage_k[z] > 0.0 ? in.coverage_k[z] : 2.0;
                const double ts = cond.zones[z].skin_temp_c;
                p.drivers["skin-air temperature difference"] = ts - cond.air_temp_c;
                p.drivers["vapour concentration difference"] =
                    cond.wettedness * (physics::saturation_concentration_kg_m3(ts) - c_air);
                p.drivers["relative humidity"] = cond.air_rh_pct;
                p.drivers["air speed"] = cond.air_speed_m_s.value_or(0.0);
                p.drivers["wall-air temperature difference"] = cond.wall_temp_c.value_or(cond.air_temp_c) - cond.air_temp_c;
                p.drivers["wettedness"] = cond.wettedness;
                if (z < in.heights_m.size()) p.drivers["zone height"] = in.heights_m[z];
                if (z < in.sides.size()) p.drivers["side (left -1, right +1)"] = in.sides[z] == "l" ? -1.0 : in.sides[z] == "r" ? 1.0 : 0.0;
                if (facing_known) p.drivers["facing (back -1, front +1)"] = cond.zones[z].facing;
                points_.push_back(std::move(p));
                index_.emplace_back(c, z);
            }
        }
        measurement_ = drift_findings();
        // The twin as given at each trial (the zones a scoped term leaves alone); none where it
        // cannot be evaluated (predict then computes every zone and fails as before).
        try {
            base_flux_ = trial_fluxes({});
        } catch (const std::exception&) {
            base_flux_.clear();
        }
    }
    const std::vector<Point>& points() const override { return points_; }
    std::vector<std::string> measurement() const override { return measurement_; }
    bool supports(const std::string&) const override { return true; }
    std::string base_name() const override { return base_.name; }

    // A case's zone whose flux still moved, in any of its replicates, by more than the steady-state
    // check's limit over the window and by more than kFluxDriftOutlier times that trial's median
    // zone: its mean is a zone still settling (a lagging sensor), not a steady flux. A whole body
    // that drifts alike (a short trial: every zone 1-4 W/m² in the daemon's simulated lab) is the
    // trial's, shared by its zones, and stays in the fit.
    static bool drifts(const TrialInput& t, std::size_t z) {
        if (z >= t.flux_drift_w_m2.size() || !(t.flux_drift_w_m2[z] > kFluxDriftLimit_w_m2)) return false;
        std::vector<double> all = t.flux_drift_w_m2;
        std::nth_element(all.begin(), all.begin() + static_cast<long>(all.size() / 2), all.end());
        return t.flux_drift_w_m2[z] > kFluxDriftOutlier * all[all.size() / 2];
    }
    static bool still_drifting(const CaseInput& in, std::size_t z) {
        for (const auto& t : in.trials)
            if (drifts(t, z)) return true;
        return false;
    }

    // What a recording cannot settle (issue 61, part 4), zones with the same cases together:
    // "zones 27 (calf_front_l), 28 (calf_front_r): the heat flux still drifts up to 6.1 W/m² ...".
    std::vector<std::string> drift_findings() const {
        struct Seen {
            double worst_w_m2 = 0.0;
            std::vector<int> cases;
            std::vector<std::string> trials;
        };
        std::map<int, Seen> by_zone;
        std::map<int, std::string> names;
        for (const auto& in : cases_)
            for (std::size_t z = 0; z < in.conditions.zones.size(); ++z) {
                if (!still_drifting(in, z)) continue;
                const int zone = in.conditions.zones[z].zone;
                Seen& seen = by_zone[zone];
                names[zone] = z < in.zone_names.size() ? in.zone_names[z] : std::string{};
                seen.cases.push_back(in.case_id);
                for (const auto& t : in.trials)
                    if (drifts(t, z)) {
                        seen.worst_w_m2 = std::max(seen.worst_w_m2, t.flux_drift_w_m2[z]);
                        seen.trials.push_back(t.id.empty() ? fmt::format("case {}", in.case_id) : t.id);
                    }
            }
        // Trials whose every zone still drifts: too short, said, and kept (the drift is the body's).
        std::vector<std::string> whole;
        double whole_worst = 0.0;
        for (const auto& in : cases_)
            for (const auto& t : in.trials) {
                if (t.flux_drift_w_m2.empty()) continue;
                std::vector<double> all = t.flux_drift_w_m2;
                std::nth_element(all.begin(), all.begin() + static_cast<long>(all.size() / 2), all.end());
                if (all[all.size() / 2] > kFluxDriftLimit_w_m2) {
                    whole.push_back(t.id.empty() ? fmt::format("case {}", in.case_id) : t.id);
                    whole_worst = std::max(whole_worst, all[all.size() / 2]);
                }
            }
        std::vector<std::string> out;
        if (!whole.empty()) {
            std::string list;
            for (std::size_t i = 0; i < whole.size() && i < 6; ++i) list += (i ? ", " : "") + whole[i];
            if (whole.size() > 6) list += fmt::format(" and {} more", whole.size() - 6);
            out.push_back(fmt::format("the whole body's flux still drifts over the steady window in {} trial{} ({}; the median "
                                      "zone up to {:.1f} W/m²): the trials may be too short for a steady heat loss; kept in "
                                      "the fit, as every zone shares it",
                                      whole.size(), whole.size() > 1 ? "s" : "", list, whole_worst));
        }
        // Zones drifting in the same cases are one finding.
        std::map<std::vector<int>, std::vector<int>> by_cases;
        for (const auto& [zone, seen] : by_zone) by_cases[seen.cases].push_back(zone);
        for (const auto& [cases, zones] : by_cases) {
            std::string who, trials;
            double worst = 0.0;
            std::size_t listed = 0, all = 0;
            for (int zone : zones) {
                who += fmt::format("{}{}{}", who.empty() ? "" : ", ", zone, names[zone].empty() ? "" : " (" + names[zone] + ")");
                worst = std::max(worst, by_zone[zone].worst_w_m2);
                for (const auto& t : by_zone[zone].trials) {
                    if (trials.find(t) != std::string::npos) continue;
                    ++all;
                    if (listed < 6) trials += (listed++ ? ", " : "") + t;
                }
            }
            if (all > listed) trials += fmt::format(" and {} more", all - listed);
            std::string case_list;
            for (int c : cases) case_list += fmt::format("{}{}", case_list.empty() ? "" : ", ", c);
            const std::size_t left_out = cases.size() * zones.size();
            out.push_back(fmt::format("zone{} {}: the heat flux still drifts up to {:.1f} W/m² over the steady window "
                                      "(case{} {}; {}): not steady, so a finding about the measurement, not physics; "
                                      "{} point{} left out of the fit; a longer trial or the flux stability rule "
                                      "(--require-flux-stability) would settle it",
                                      zones.size() > 1 ? "s" : "", who, worst, cases.size() > 1 ? "s" : "", case_list, trials,
                                      left_out, left_out > 1 ? "s" : ""));
        }
        return out;
    }
    std::vector<tw::Term> base_terms() const override { return base_.terms; }

    // A case's prediction is the mean of the twin at each replicate's own recorded conditions, as
    // the observation is the mean of the replicates' fluxes: near the kink of |dT|^(1/4) at dT = 0
    // the twin at the mean conditions is not the mean of the twin (replicates straddle the kink),
    // and that difference biased a fitted air-probe bias by 10 %.
    std::vector<double> predict(const std::vector<tw::Term>& extra) const override {
        tw::TwinVersion v = base_;
        v.terms.insert(v.terms.end(), extra.begin(), extra.end());
        const tw::ResolvedVersion resolved = tw::resolve(v);  // the terms read once, not per trial
        // Terms scoped to some zones (a region's wet fraction, 16 of the demo's 22 candidates,
        // 1-4 zones of 35) leave the other zones where the remaining terms put them: those are
        // taken from the twin as given (kept) or from this thread's last four predictions with the
        // same other terms (a pair's scan and the steps of its fit in the scoped term), and only the
        // touched zones are computed. The same numbers: each zone's flux is its own.
        std::vector<tw::Term> global;
        bool scoped = false;
        for (const auto& t : extra) {
            if (zone_scoped(t)) scoped = true;
            else global.push_back(t);
        }
        if (scoped && !base_flux_.empty()) {
            try {
                return average(resolved, extra, global.empty() ? base_flux_ : others(global));
            } catch (const std::exception&) {
                // computed in full below, failing as it always did
            }
        }
        return average(resolved, {}, {});
    }

    // A term that changes only some zones: a region's wet fraction or garment, some zones' leak or gain.
    static bool zone_scoped(const tw::Term& t) {
        return t.name == "partial_wettedness" || t.name == "clothing" || t.name == "heat_leak" || t.name == "zone_gain";
    }
    static bool touches(const tw::Term& t, const tw::ZoneInput& z) {
        if (t.name == "partial_wettedness" || t.name == "clothing") return t.region == z.region;
        return std::find(t.zones.begin(), t.zones.end(), z.zone) != t.zones.end();
    }
    static bool same_terms(const std::vector<tw::Term>& a, const std::vector<tw::Term>& b) {
        if (a.size() != b.size()) return false;
        for (std::size_t i = 0; i < a.size(); ++i)
            if (a[i].name != b[i].name || a[i].region != b[i].region || a[i].zones != b[i].zones || a[i].parameters != b[i].parameters ||
                a[i].input != b[i].input || a[i].pattern != b[i].pattern)
                return false;
        return true;
    }

    // Each case's prediction, the mean over its trials of the twin (its zones' q_total): every
    // zone computed, or (`rest` given) only those a term of `scoped` touches and the others from `rest`.
    using TrialFluxes = std::vector<std::vector<std::vector<double>>>;  // [case][trial used][zone], W/m²
    std::vector<double> average(const tw::ResolvedVersion& resolved, const std::vector<tw::Term>& scoped, const TrialFluxes& rest) const {
        std::vector<tw::ZoneFlux> f;
        std::vector<char> touched;
        auto run = [&](std::size_t c, std::size_t slot, const tw::TrialConditions& cond) {
            if (rest.empty()) {
                tw::predict(resolved, cond, f);
                return;
            }
            touched.assign(cond.zones.size(), 0);
            for (std::size_t z = 0; z < cond.zones.size(); ++z)
                for (const auto& t : scoped) touched[z] = touched[z] || touches(t, cond.zones[z]);
            tw::predict(resolved, cond, f, &touched);
            for (std::size_t z = 0; z < cond.zones.size(); ++z)
                if (!touched[z]) f[z].q_total_w_m2 = rest.at(c).at(slot).at(z);
        };
        std::vector<std::vector<double>> per_case(cases_.size());
        for (std::size_t c = 0; c < cases_.size(); ++c) {
            const auto& in = cases_[c];
            const std::size_t z_count = in.conditions.zones.size();
            std::vector<double>& q = per_case[c];
            q.assign(z_count, 0.0);
            int used = 0;
            for (const auto& t : in.trials) {
                if (t.conditions.zones.size() != z_count) continue;
                run(c, static_cast<std::size_t>(used), t.conditions);
                for (std::size_t z = 0; z < z_count; ++z) q[z] += f[z].q_total_w_m2;
                ++used;
            }
            if (used == 0) {
                run(c, 0, in.conditions);
                for (std::size_t z = 0; z < z_count; ++z) q[z] = f[z].q_total_w_m2;
            } else {
                for (double& x : q) x /= used;
            }
        }
        std::vector<double> out(points_.size());
        for (std::size_t i = 0; i < points_.size(); ++i) out[i] = per_case[index_[i].first][index_[i].second];
        return out;
    }

    // Every trial's zones under the twin as given plus `terms` (the slots `average` reads).
    TrialFluxes trial_fluxes(const std::vector<tw::Term>& terms) const {
        tw::TwinVersion v = base_;
        v.terms.insert(v.terms.end(), terms.begin(), terms.end());
        const tw::ResolvedVersion resolved = tw::resolve(v);
        std::vector<tw::ZoneFlux> f;
        TrialFluxes out(cases_.size());
        auto keep = [&](std::vector<std::vector<double>>& slots, const tw::TrialConditions& cond) {
            tw::predict(resolved, cond, f);
            std::vector<double> q(f.size());
            for (std::size_t z = 0; z < f.size(); ++z) q[z] = f[z].q_total_w_m2;
            slots.push_back(std::move(q));
        };
        for (std::size_t c = 0; c < cases_.size(); ++c) {
            const auto& in = cases_[c];
            for (const auto& t : in.trials)
                if (t.conditions.zones.size() == in.conditions.zones.size()) keep(out[c], t.conditions);
            if (out[c].empty()) keep(out[c], in.conditions);
        }
        return out;
    }

    // This thread's last four trial fluxes under terms that touch every zone, kept by model and
    // terms (four: a fit's steps in the scoped term come back to its point after steps in another,
    // up and down for its covariance).
    const TrialFluxes& others(const std::vector<tw::Term>& global) const {
        struct Memo {
            std::uint64_t model = 0;
            std::uint64_t used = 0;  // when last asked for (the oldest is replaced)
            std::vector<tw::Term> terms;
            TrialFluxes fluxes;
        };
        thread_local std::array<Memo, 4> memo;
        thread_local std::uint64_t clock = 0;
        ++clock;
        for (auto& m : memo)
            if (m.model == id_ && same_terms(m.terms, global)) {
                m.used = clock;
                return m.fluxes;
            }
        Memo& m = *std::min_element(memo.begin(), memo.end(), [](const Memo& x, const Memo& y) { return x.used < y.used; });
        m.model = 0;  // not valid until filled (trial_fluxes may throw)
        m.fluxes = trial_fluxes(global);
        m.terms = global;
        m.model = id_;
        m.used = clock;
        return m.fluxes;
    }

    // Per case: the twin's response (W/m² per zone) to one unit of each shared error: air
    // temperature (°C), humidity (% RH), wall temperature (°C), a manikin gain and an offset.
    // The slopes are secants, not derivatives at a point: |dT|^(1/4) has a kink at dT = 0, where a
    // derivative misstates how the flux moves over the range the error really spans (GUM
    // Supplement 1's concern with linearisation). So the span is the error's own:
    // - `Span::calibration`, the probes' Type B: +-2 standard uncertainties of each probe;
    // - `Span::trial`, each trial's own shared errors (a trial's probe and condition scatter, some
    //   0.05 °C and 0.5 % RH): +-0.05 °C, +-0.25 % RH. Over the calibration's +-0.23 °C the
    //   isothermal wet cases' secant is a fraction of their slope at the trial's scale, and the
    //   scatter estimate made up for it: 0.1-0.25 °C of per-trial air error (and 0-4.5 % RH)
    //   fitted to the generator's 0.05 °C (0.5 % RH), which the planner's draws then pushed
    //   through every case, hiding humidity buoyancy and the air bias (docs/notes/reconcile-history.md, fifth pass).
    enum class Span { calibration, trial };
    static Eigen::MatrixXd case_loadings(const tw::TwinVersion& physics, const CaseInput& in,
                                         const std::vector<tw::ZoneFlux>& twin_case, const Instruments& instruments, Span span) {
        const auto z_count = static_cast<Eigen::Index>(in.conditions.zones.size());
        Eigen::MatrixXd j = Eigen::MatrixXd::Zero(z_count, 5);
        auto column = [&](Eigen::Index k, double step, auto apply) {
            tw::TrialConditions up = in.conditions, down = in.conditions;
            apply(up, step);
            apply(down, -step);
            const auto fu = tw::predict(physics, up), fd = tw::predict(physics, down);
            for (Eigen::Index z = 0; z < z_count; ++z)
                j(z, k) = (fu[static_cast<std::size_t>(z)].q_total_w_m2 - fd[static_cast<std::size_t>(z)].q_total_w_m2) / (2.0 * step);
        };
        const auto& cond = in.conditions;
        const bool cal = span == Span::calibration;
        column(0, cal ? std::max(0.05, 2.0 * spec_u(instruments, "air_temp_c", cond.air_temp_c)) : 0.05,
               [](tw::TrialConditions& t, double d) { t.air_temp_c += d; });
        column(1, cal ? std::max(0.25, 2.0 * spec_u(instruments, "air_rh_pct", cond.air_rh_pct)) : 0.25,
               [](tw::TrialConditions& t, double d) { t.air_rh_pct += d; });
        if (cond.wall_temp_c)
            column(2, cal ? std::max(0.05, 2.0 * spec_u(instruments, "wall_temp_c", *cond.wall_temp_c)) : 0.05,
                   [](tw::TrialConditions& t, double d) { *t.wall_temp_c += d; });
        for (Eigen::Index z = 0; z < z_count; ++z) {
            j(z, 3) = twin_case[static_cast<std::size_t>(z)].q_total_w_m2;
            j(z, 4) = 1.0;
        }
        return j;
    }

    // The even part of the twin's response to a symmetric error in input k (0 air °C, 1 RH %, 2
    // wall °C): s(e) = (f(x + e) + f(x - e)) / 2 - f(x), at four equiprobable magnitudes |e|, halved
    // so that their second moment is sum v v'. The secant loadings hold only the odd part; where a
    // zone's air crosses its skin (the wet isothermal cases, a vertical gradient) h_c ~ |dT|^(1/4)
    // (Eq. 5) turns either sign of error into more evaporation, an even response the secant reads
    // as none: one trial's 0.1 K air error moved a hand 24 W/m² there (issue 61). Not centred: its
    // mean is the bias of a twin evaluated at the recorded conditions instead of the real ones
    // (Jensen), uncorrected and so counted in the uncertainty (GUM F.2.4.5); centred, one gradient
    // interval in twelve missed. Empty where the input is absent.
    static std::vector<Eigen::VectorXd> even_responses(const tw::TwinVersion& physics, const tw::TrialConditions& cond,
                                                      const std::vector<tw::ZoneFlux>& at, int k,
                                                      const std::array<double, 4>& magnitudes) {
        std::vector<Eigen::VectorXd> out;
        if (k == 2 && !cond.wall_temp_c) return out;
        const auto z_count = static_cast<Eigen::Index>(at.size());
        auto shifted = [&](double d) {
            tw::TrialConditions t = cond;
            if (k == 0) t.air_temp_c += d;
            else if (k == 1) t.air_rh_pct = std::clamp(t.air_rh_pct + d, 0.0, 100.0);
            else *t.wall_temp_c += d;
            return tw::predict(physics, t);
        };
        for (double e : magnitudes) {
            if (!(e > 0.0)) return {};
            const auto up = shifted(e), down = shifted(-e);
            Eigen::VectorXd v(z_count);
            for (Eigen::Index z = 0; z < z_count; ++z) {
                const auto zi = static_cast<std::size_t>(z);
                v(z) = 0.5 * (up[zi].q_total_w_m2 + down[zi].q_total_w_m2) - at[zi].q_total_w_m2;
            }
            out.push_back(std::move(v));
        }
        for (auto& v : out) v = 0.5 * v;
        return out;
    }
    // |e| at the midpoints of its quartiles, per unit sd (normal) or unit half-width (rectangular).
    static constexpr std::array<double, 4> kNormalQuartiles = {0.157, 0.489, 0.887, 1.534};
    static constexpr std::array<double, 4> kRectangularQuartiles = {0.125, 0.375, 0.625, 0.875};

    // The noise model's pieces: the replicates' residuals with the twin's sensitivities (what
    // the random part is estimated from) and the Type B parts, which are specified, not estimated.
    struct NoiseParts {
        ReplicateResiduals data;
        Eigen::MatrixXd systematic;   // probes (P) and the manikin's calibration (K)
        Eigen::MatrixXd shared_probes;  // n x (3 + 4 per probe with an even part): the probes' part common to every case
        std::vector<Eigen::MatrixXd> calibration_loadings;  // per case, over the probes' Type B span
        std::vector<std::vector<tw::ZoneFlux>> twin_cases;   // per case, the twin at its mean conditions
        tw::TwinVersion physics;      // the twin the sensitivities are of
        NoiseModel meta;              // everything but the covariances
    };

    NoiseParts noise_parts(const Instruments& instruments, double shared_fraction, const std::vector<tw::Term>& with) const {
        tw::TwinVersion physics = base_;
        physics.terms.insert(physics.terms.end(), with.begin(), with.end());
        const std::size_t n = points_.size();
        NoiseParts parts;
        NoiseModel& out = parts.meta;
        out.point_replicates.resize(n, 1);

        // Random part: each trial's residual against the twin at that trial's own recorded
        // conditions, so condition changes between replicates are not counted as noise.
        ReplicateResiduals& data = parts.data;
        data.factor_start_sd = {0.1, 0.5, 0.2, 0.01, 0.3};
        for (const auto& in : cases_) {
            const std::size_t z_count = in.conditions.zones.size();
            std::vector<std::vector<double>> trials;
            for (const auto& t : in.trials) {
                if (t.q_w_m2.size() != z_count || t.conditions.zones.size() != z_count) continue;
                const auto twin = tw::predict(physics, t.conditions);
                std::vector<double> r(z_count);
                for (std::size_t z = 0; z < z_count; ++z) r[z] = t.q_w_m2[z] - twin[z].q_total_w_m2;
                trials.push_back(std::move(r));
            }
            // Flux-proportional parts (relative scatter, gains) scale with the twin's prediction,
            // not the observation: a covariance built from the data it judges biases GLS toward
            // smaller values (Peelle's pertinent puzzle).
            const auto twin_case = tw::predict(physics, in.conditions);
            std::vector<double> abs_q(z_count);
            for (std::size_t z = 0; z < z_count; ++z) abs_q[z] = std::abs(twin_case[z].q_total_w_m2);
            data.residual_w_m2.push_back(std::move(trials));
            data.abs_flux_w_m2.push_back(std::move(abs_q));
            data.loadings.push_back(case_loadings(physics, in, twin_case, instruments, Span::trial));
            parts.calibration_loadings.push_back(case_loadings(physics, in, twin_case, instruments, Span::calibration));
            parts.twin_cases.push_back(twin_case);
        }
        parts.physics = physics;

        const auto flux = instruments.count("heat_flux_w_m2") ? instruments.at("heat_flux_w_m2") : InstrumentSpec{};
        out.calibration_offset_u_w_m2 = flux.standard_uncertainty(0.0);
        out.calibration_gain_u = flux.standard_uncertainty(1.0) - out.calibration_offset_u_w_m2;
        out.air_temp_u_c = spec_u(instruments, "air_temp_c", 0.0);
        out.probe_shared_fraction = shared_fraction;
        out.wall_temp_u_c = spec_u(instruments, "wall_temp_c", 0.0);
        if (instruments.count("air_rh_pct")) {
            const auto& rh = instruments.at("air_rh_pct");
            out.rh_u_text = fmt::format("{:.3g} + {:.3g} RH % (standard)", rh.standard_uncertainty(0.0),
                                        rh.standard_uncertainty(100.0) / 100.0 - rh.standard_uncertainty(0.0) / 100.0);
        }

        const auto nn = static_cast<Eigen::Index>(n);
        parts.systematic = Eigen::MatrixXd::Zero(nn, nn);
        parts.shared_probes = Eigen::MatrixXd::Zero(nn, 0);
        std::vector<std::vector<std::size_t>> rows(cases_.size());
        for (std::size_t i = 0; i < n; ++i) rows[index_[i].first].push_back(i);
        // The probes' Type B errors act through the twin's response (columns over every point).
        // Part of that variance is the probe's calibration, the same in every case
        // (`probe_shared_fraction`, a shared column); the rest differs from case to case (the
        // error's dependence on temperature and humidity) and is shared by one case's zones only.
        auto add_probe_part = [&](const Eigen::MatrixXd& cols) {
            parts.systematic += shared_fraction * cols * cols.transpose();
            for (std::size_t c = 0; c < cases_.size(); ++c)
                for (std::size_t a : rows[c])
                    for (std::size_t b : rows[c])
                        parts.systematic(static_cast<Eigen::Index>(a), static_cast<Eigen::Index>(b)) +=
                            (1.0 - shared_fraction) * cols.row(static_cast<Eigen::Index>(a)).dot(cols.row(static_cast<Eigen::Index>(b)));
            const Eigen::Index at = parts.shared_probes.cols();
            parts.shared_probes.conservativeResize(Eigen::NoChange, at + cols.cols());
            parts.shared_probes.rightCols(cols.cols()) = std::sqrt(shared_fraction) * cols;
        };
        // The odd part, through the secant loadings: one column per probe, always three.
        for (Eigen::Index k = 0; k < 3; ++k) {
            Eigen::MatrixXd g = Eigen::MatrixXd::Zero(nn, 1);
            for (std::size_t c = 0; c < cases_.size(); ++c) {
                const auto& cond = cases_[c].conditions;
                const double u = k == 0   ? spec_u(instruments, "air_temp_c", cond.air_temp_c)
                                 : k == 1 ? spec_u(instruments, "air_rh_pct", cond.air_rh_pct)
                                 : cond.wall_temp_c ? spec_u(instruments, "wall_temp_c", *cond.wall_temp_c)
                                                    : 0.0;
                for (std::size_t a : rows[c])
                    g(static_cast<Eigen::Index>(a), 0) = u * parts.calibration_loadings[c](static_cast<Eigen::Index>(index_[a].second), k);
            }
            add_probe_part(g);
        }
        // The even part (even_responses), within each probe's limit (rectangular): four columns
        // per probe where it is not zero.
        for (int k = 0; k < 3; ++k) {
            const char* channel = k == 0 ? "air_temp_c" : k == 1 ? "air_rh_pct" : "wall_temp_c";
            Eigen::MatrixXd cols = Eigen::MatrixXd::Zero(nn, 4);
            for (std::size_t c = 0; c < cases_.size(); ++c) {
                const auto& cond = cases_[c].conditions;
                const double reading = k == 0 ? cond.air_temp_c : k == 1 ? cond.air_rh_pct : cond.wall_temp_c.value_or(0.0);
                const double limit = spec_limit(instruments, channel, reading);
                std::array<double, 4> m{};
                for (std::size_t i = 0; i < 4; ++i) m[i] = limit * kRectangularQuartiles[i];
                const auto vs = even_responses(physics, cond, parts.twin_cases[c], k, m);
                for (std::size_t i = 0; i < vs.size(); ++i)
                    for (std::size_t a : rows[c])
                        cols(static_cast<Eigen::Index>(a), static_cast<Eigen::Index>(i)) = vs[i](static_cast<Eigen::Index>(index_[a].second));
            }
            if (cols.squaredNorm() > 0.0) add_probe_part(cols);
        }
        for (std::size_t c = 0; c < cases_.size(); ++c)
            for (std::size_t a : rows[c]) out.point_replicates[a] = std::max<int>(1, static_cast<int>(cases_[c].trials.size()));
        return parts;
    }

    // This campaign's scatter model: estimated from its replicates, else carried from an earlier
    // campaign, else not estimable.
    ScatterModel scatter_of(const ScatterModel& own) const {
        if (own.estimable || !carried_) return own;
        return to_scatter(*carried_);
    }

    ScatterModel to_scatter(const CarriedNoise& c) const {
        ScatterModel s;
        s.estimable = true;
        s.dof = c.dof;
        s.relative_sd = c.relative_sd;
        s.factor_sd = c.factor_sd;
        double mean_sd = 0.0;
        for (const auto& [zone, sd] : c.zone_sd_w_m2) mean_sd += sd / static_cast<double>(c.zone_sd_w_m2.size());
        const auto& zones = first_zones();
        for (const auto& z : zones) {
            const auto it = c.zone_sd_w_m2.find(z.zone);
            s.zone_sd_w_m2.push_back(it == c.zone_sd_w_m2.end() ? mean_sd : it->second);
        }
        return s;
    }

    // The whole covariance from a scatter model: the random part of each case mean (the trial
    // covariance over the replicates) plus the Type B parts.
    // `shared_out`: the directions shared by every case (NoiseModel::shared_factor).
    Eigen::MatrixXd assemble(const NoiseParts& parts, const ScatterModel& scatter, Eigen::MatrixXd* random_out,
                             int replicates = 0, Eigen::MatrixXd* shared_out = nullptr) const {
        const std::size_t n = points_.size();
        const auto nn = static_cast<Eigen::Index>(n);
        Eigen::MatrixXd random = Eigen::MatrixXd::Zero(nn, nn);
        std::vector<std::vector<std::size_t>> rows(cases_.size());
        for (std::size_t i = 0; i < n; ++i) rows[index_[i].first].push_back(i);
        for (std::size_t c = 0; c < cases_.size(); ++c) {
            const int reps = replicates > 0 ? replicates : std::max<int>(1, static_cast<int>(cases_[c].trials.size()));
            Eigen::MatrixXd trial_cov;
            if (scatter.estimable) {
                trial_cov = scatter.trial_covariance(parts.data.abs_flux_w_m2[c], parts.data.loadings[c]);
                // The even part of the twin's response to each trial's own air, humidity and wall
                // errors (even_responses), at the scatter's own sd per trial.
                for (int k = 0; k < 3 && static_cast<std::size_t>(k) < scatter.factor_sd.size(); ++k) {
                    const double tau = scatter.factor_sd[static_cast<std::size_t>(k)];
                    if (!(tau > 0.0)) continue;
                    std::array<double, 4> m{};
                    for (std::size_t i = 0; i < 4; ++i) m[i] = tau * kNormalQuartiles[i];
                    for (const auto& v : even_responses(parts.physics, cases_[c].conditions, parts.twin_cases[c], k, m))
                        trial_cov += v * v.transpose();
                }
            }
            for (std::size_t a : rows[c])
                for (std::size_t b : rows[c]) {
                    double cov = 0.0;
                    if (scatter.estimable)
                        cov = trial_cov(static_cast<Eigen::Index>(index_[a].second), static_cast<Eigen::Index>(index_[b].second));
                    else if (a == b)
                        cov = points_[a].standard_u() * points_[a].standard_u() * reps;
                    random(static_cast<Eigen::Index>(a), static_cast<Eigen::Index>(b)) = cov / reps;
                }
        }
        Eigen::MatrixXd total = random;
        if (scatter.estimable) {
            total += parts.systematic;
            // The manikin's calibration: one offset and one gain error shared by every zone and
            // case. Without replicates each point's own U/k already holds the heat-flux Type B,
            // so it is not added again (counted once).
            const auto& m = parts.meta;
            for (std::size_t a = 0; a < n; ++a) {
                const double sa = parts.data.loadings[index_[a].first](static_cast<Eigen::Index>(index_[a].second), 3);
                for (std::size_t b = 0; b < n; ++b) {
                    const double sb = parts.data.loadings[index_[b].first](static_cast<Eigen::Index>(index_[b].second), 3);
                    total(static_cast<Eigen::Index>(a), static_cast<Eigen::Index>(b)) +=
                        m.calibration_offset_u_w_m2 * m.calibration_offset_u_w_m2 + m.calibration_gain_u * m.calibration_gain_u * sa * sb;
                }
            }
        } else {
            // The probes' part is not in a point's U (the analysis's GUM budget is of the flux).
            total += parts.systematic;
        }
        // A hair of independent noise keeps the covariance positive definite when the random
        // part is tiny (synthetic data) and the systematic parts are of low rank.
        total.diagonal().array() += 1e-9 * total.diagonal().mean() + 1e-12;
        if (random_out) *random_out = std::move(random);
        if (shared_out) {
            // The probes' common part, and with replicates the calibration's offset and gain.
            Eigen::MatrixXd& u = *shared_out;
            u.resize(nn, parts.shared_probes.cols() + (scatter.estimable ? 2 : 0));
            u.leftCols(parts.shared_probes.cols()) = parts.shared_probes;
            if (scatter.estimable) {
                const auto& m = parts.meta;
                const Eigen::Index k = parts.shared_probes.cols();
                for (std::size_t a = 0; a < n; ++a) {
                    const double sa = parts.data.loadings[index_[a].first](static_cast<Eigen::Index>(index_[a].second), 3);
                    u(static_cast<Eigen::Index>(a), k) = m.calibration_offset_u_w_m2;
                    u(static_cast<Eigen::Index>(a), k + 1) = m.calibration_gain_u * sa;
                }
            }
        }
        return total;
    }

    NoiseModel noise_model(const Instruments& instruments, double shared_fraction,
                           const std::vector<tw::Term>& with) const override {
        NoiseParts parts = noise_parts(instruments, shared_fraction, with);
        NoiseModel out = parts.meta;
        const ScatterModel own = estimate_scatter(parts.data);
        const ScatterModel scatter = scatter_of(own);
        out.from_replicates = own.estimable;
        out.carried_from = !own.estimable && carried_ ? carried_->source : "";
        if (own.estimable) {
            out.scatter_steps = own.iterations;
            out.scatter_converged = own.converged;
            if (!own.converged)
                out.notes.push_back(fmt::format("the replicate scatter's estimate stopped at its cap of {} steps before the "
                                                "likelihood settled: its per-trial shared errors may be off",
                                                own.iterations));
        }
        out.random_dof = scatter.dof;
        out.relative_sd = scatter.relative_sd;
        out.zone_prior_dof = scatter.zone_prior_dof;
        if (scatter.estimable) {
            const char* names[] = {"air °C", "RH %", "wall °C", "gain", "offset W/m²"};
            for (std::size_t k = 0; k < scatter.factor_sd.size() && k < 5; ++k) out.trial_factor_sd.emplace_back(names[k], scatter.factor_sd[k]);
            const auto& zones = first_zones();
            for (std::size_t z = 0; z < zones.size() && z < scatter.zone_sd_w_m2.size(); ++z)
                out.zone_sd_w_m2[zones[z].zone] = scatter.zone_sd_w_m2[z];
        }
        if (!own.estimable && carried_)
            out.notes.push_back(fmt::format("one replicate per case: the replicate scatter is carried from {} ({} dof)",
                                            carried_->source, carried_->dof));
        else if (!own.estimable)
            out.notes.push_back("no case has two replicates: the random part is each point's own standard "
                                "uncertainty from the analysis, taken as independent (a lower bound: no claim "
                                "is made on it; --noise-from carries a lab's scatter from a campaign with replicates)");
        out.covariance = assemble(parts, scatter, &out.random_covariance, 0, &out.shared_factor);
        return out;
    }

    // Replicates simulated from the fitted scatter model and estimated again (the estimate's own
    // scatter), the Type B parts as specified.
    class Resampler final : public NoiseResampler {
    public:
        Resampler(const TwinModel& model, NoiseParts parts, ScatterModel fitted, bool own)
            : model_(model), parts_(std::move(parts)), fitted_(std::move(fitted)), own_(own) {}
        Eigen::MatrixXd draw(std::uint64_t seed, int replicates) const override {
            ScatterModel again;
            if (own_) {
                ReplicateResiduals shape = parts_.data;
                if (replicates > 0)
                    for (auto& trials : shape.residual_w_m2)
                        if (!trials.empty()) trials.resize(static_cast<std::size_t>(replicates), trials.front());
                again = estimate_scatter(simulate_residuals(shape, fitted_, seed));
            } else {
                const CarriedNoise c = model_.carried_->redraw ? model_.carried_->redraw(seed) : *model_.carried_;
                again = model_.to_scatter(c);
            }
            return model_.assemble(parts_, again, nullptr, replicates);
        }

    private:
        const TwinModel& model_;
        NoiseParts parts_;
        ScatterModel fitted_;
        bool own_;
    };

    std::unique_ptr<NoiseResampler> noise_resampler(const Instruments& instruments, double shared_fraction,
                                                    const std::vector<tw::Term>& with) const override {
        NoiseParts parts = noise_parts(instruments, shared_fraction, with);
        ScatterModel own = estimate_scatter(parts.data);
        if (own.estimable) return std::make_unique<Resampler>(*this, std::move(parts), std::move(own), true);
        if (carried_) return std::make_unique<Resampler>(*this, std::move(parts), ScatterModel{}, false);
        return nullptr;
    }

    // Campaigns of this design drawn anew (for `--power`). Everything comes from this campaign:
    // the spread of the replicates' recorded conditions about their case mean (pooled over cases:
    // air, humidity, wall, each zone's skin), the fitted scatter model (sigma0, kappa, the tau of
    // the per-trial shared errors) and the instruments' Type B. A new campaign's case mean lands
    // about this one's with the planning mean's own error (sd s/sqrt(n_here)) plus the new
    // replicates' (s/sqrt(n)); with one replicate per case (scatter carried) that spread is
    // unknown and taken as 0. The recorded conditions differ from the true ones by the probes'
    // calibration errors (the part common to every case: `shared_fraction`); the flux is the twin
    // with `truth` at the true conditions, through the manikin's calibration gain and offset,
    // plus each trial's shared errors acting linearly through the case's sensitivities (as the
    // scatter model fitted them) and each zone's own scatter. The twin is evaluated, not
    // linearised: near the isothermal cases' kink where the conditions land decides detectability.
    class Simulator final : public CampaignSimulator {
    public:
        Simulator(const TwinModel& model, NoiseParts parts, ScatterModel scatter, const Instruments& instruments,
                  double shared_fraction)
            : model_(model), parts_(std::move(parts)), scatter_(std::move(scatter)), instruments_(instruments),
              phi_(std::clamp(shared_fraction, 0.0, 1.0)) {
            const std::size_t z_count = model_.first_zones().size();
            // Pooled within-case spread of the recorded conditions.
            double ss_air = 0.0, ss_rh = 0.0, ss_wall = 0.0;
            std::vector<double> ss_skin(z_count, 0.0);
            int dof = 0;
            for (const auto& in : model_.cases_) {
                if (in.trials.size() < 2 || in.conditions.zones.size() != z_count) continue;
                for (const auto& t : in.trials) {
                    if (t.conditions.zones.size() != z_count) continue;
                    ss_air += std::pow(t.conditions.air_temp_c - in.conditions.air_temp_c, 2);
                    ss_rh += std::pow(t.conditions.air_rh_pct - in.conditions.air_rh_pct, 2);
                    if (t.conditions.wall_temp_c && in.conditions.wall_temp_c)
                        ss_wall += std::pow(*t.conditions.wall_temp_c - *in.conditions.wall_temp_c, 2);
                    for (std::size_t z = 0; z < z_count; ++z)
                        ss_skin[z] += std::pow(t.conditions.zones[z].skin_temp_c - in.conditions.zones[z].skin_temp_c, 2);
                }
                dof += static_cast<int>(in.trials.size()) - 1;
            }
            const double d = std::max(1, dof);
            s_air_ = std::sqrt(ss_air / d);
            s_rh_ = std::sqrt(ss_rh / d);
            s_wall_ = std::sqrt(ss_wall / d);
            s_skin_.resize(z_count);
            for (std::size_t z = 0; z < z_count; ++z) s_skin_[z] = std::sqrt(ss_skin[z] / d);

            flux_ = instruments_.count("heat_flux_w_m2") ? instruments_.at("heat_flux_w_m2") : InstrumentSpec{};
        }

        std::unique_ptr<ForwardModel> draw(const std::vector<tw::Term>& truth, int replicates, std::uint64_t seed,
                                           std::vector<tw::Term>* calibration = nullptr,
                                           std::vector<DrawnCalibrationError>* errors = nullptr) const override {
            if (replicates < 1) return nullptr;
            const std::size_t z_count = model_.first_zones().size();
            const ScatterModel& scatter = scatter_;
            const Instruments& instruments = instruments_;
            const NoiseParts& parts = parts_;
            const double phi = phi_, s_air = s_air_, s_rh = s_rh_, s_wall = s_wall_;
            const std::vector<double>& s_skin = s_skin_;
            std::mt19937_64 rng(seed);
            std::normal_distribution<double> unit(0.0, 1.0);
            auto tau = [&](std::size_t k) { return k < scatter.factor_sd.size() ? scatter.factor_sd[k] : 0.0; };
            // A calibration error in units of the spec's limit, from the distribution its Type B
            // assumes (GUM 4.3.7: rectangular within the limit unless the spec says otherwise). A
            // normal of the same u has tails past the limit: larger probe errors, which showed as
            // the air bias or the wall beside the concealed term (docs/reconcile.md).
            auto calibration_error = [&](const char* channel) {
                const auto it = instruments.find(channel);
                return standardised_error_draw(it == instruments.end() ? Distribution::rectangular : it->second.distribution, rng);
            };
            const double probe_air = calibration_error("air_temp_c"), probe_rh = calibration_error("air_rh_pct"),
                         probe_wall = calibration_error("wall_temp_c");
            const double campaign_offset = flux_.limit(0.0) * standardised_error_draw(flux_.distribution, rng);
            const double campaign_gain = (flux_.limit(1.0) - flux_.limit(0.0)) * standardised_error_draw(flux_.distribution, rng);
            if (errors) {
                errors->clear();
                if (!model_.cases_.empty()) {
                    const auto& c0 = model_.cases_.front().conditions;
                    errors->push_back({"air_temp_c", probe_air, spec_limit(instruments, "air_temp_c", c0.air_temp_c)});
                    errors->push_back({"air_rh_pct", probe_rh, spec_limit(instruments, "air_rh_pct", c0.air_rh_pct)});
                    if (c0.wall_temp_c) errors->push_back({"wall_temp_c", probe_wall, spec_limit(instruments, "wall_temp_c", *c0.wall_temp_c)});
                }
                const double offset_limit = flux_.limit(0.0), gain_limit = flux_.limit(1.0) - flux_.limit(0.0);
                if (offset_limit > 0.0) errors->push_back({"heat_flux_offset", campaign_offset / offset_limit, offset_limit});
                if (gain_limit > 0.0) errors->push_back({"heat_flux_gain", campaign_gain / gain_limit, gain_limit});
            }
            if (calibration) {
                // The common part of each probe's error at the first case's reading (the twin's
                // terms are one value for every case; with phi = 1, as the planner draws, exact).
                calibration->clear();
                if (!model_.cases_.empty() && phi > 0.0) {
                    const auto& c0 = model_.cases_.front().conditions;
                    calibration->push_back(
                        {"air_temp_bias", {{"bias_c", std::sqrt(phi) * spec_limit(instruments, "air_temp_c", c0.air_temp_c) * probe_air}}, "", {}});
                    if (c0.wall_temp_c)
                        calibration->push_back(
                            {"wall_offset", {{"delta_c", -std::sqrt(phi) * spec_limit(instruments, "wall_temp_c", *c0.wall_temp_c) * probe_wall}}, "", {}});
                }
            }
            tw::TwinVersion world = model_.base_;
            world.terms.insert(world.terms.end(), truth.begin(), truth.end());

            std::vector<CaseInput> out;
            out.reserve(model_.cases_.size());
            for (std::size_t ci = 0; ci < model_.cases_.size(); ++ci) {
                const CaseInput& in = model_.cases_[ci];
                if (in.conditions.zones.size() != z_count) continue;
                const Eigen::MatrixXd& loadings = parts.data.loadings[ci];
                const double here = std::sqrt(1.0 / std::max<double>(1.0, static_cast<double>(in.trials.size())));
                const auto& mean = in.conditions;
                tw::TrialConditions centre = mean;
                centre.air_temp_c += s_air * here * unit(rng);
                centre.air_rh_pct += s_rh * here * unit(rng);
                if (centre.wall_temp_c) *centre.wall_temp_c += s_wall * here * unit(rng);
                for (std::size_t z = 0; z < z_count; ++z) centre.zones[z].skin_temp_c += s_skin[z] * here * unit(rng);
                // This case's probe errors: the calibration part common to every case, the rest its own.
                auto probe = [&](const char* channel, double reading, double common) {
                    return spec_limit(instruments, channel, reading) * (std::sqrt(phi) * common + std::sqrt(1.0 - phi) * calibration_error(channel));
                };
                const double e_air = probe("air_temp_c", mean.air_temp_c, probe_air);
                const double e_rh = probe("air_rh_pct", mean.air_rh_pct, probe_rh);
                const double e_wall = mean.wall_temp_c ? probe("wall_temp_c", *mean.wall_temp_c, probe_wall) : 0.0;

                CaseInput c = in;
                c.trials.clear();
                c.q_exp_w_m2.assign(z_count, 0.0);
                tw::TrialConditions sum = mean;
                sum.air_temp_c = sum.air_rh_pct = 0.0;
                if (sum.wall_temp_c) *sum.wall_temp_c = 0.0;
                for (auto& z : sum.zones) z.skin_temp_c = 0.0;
                for (int r = 0; r < replicates; ++r) {
                    TrialInput t;
                    t.conditions = centre;
                    t.conditions.air_temp_c += s_air * unit(rng);
                    t.conditions.air_rh_pct += s_rh * unit(rng);
                    if (t.conditions.wall_temp_c) *t.conditions.wall_temp_c += s_wall * unit(rng);
                    for (std::size_t z = 0; z < z_count; ++z) t.conditions.zones[z].skin_temp_c += s_skin[z] * unit(rng);
                    tw::TrialConditions real = t.conditions;  // what the chamber really was
                    real.air_temp_c -= e_air;
                    real.air_rh_pct = std::clamp(real.air_rh_pct - e_rh, 0.5, 99.5);
                    if (real.wall_temp_c) *real.wall_temp_c -= e_wall;
                    // Each trial's own shared errors act as the scatter model fitted them: linearly,
                    // through the case's sensitivities (their estimate is rough, and pushed through
                    // the twin's kink it would scatter the isothermal cases more than the data did).
                    const double eta_air = tau(0) * unit(rng), eta_rh = tau(1) * unit(rng), eta_wall = tau(2) * unit(rng);
                    const double gain = campaign_gain + tau(3) * unit(rng), offset = campaign_offset + tau(4) * unit(rng);
                    const auto q = tw::predict(world, real);
                    t.q_w_m2.resize(z_count);
                    for (std::size_t z = 0; z < z_count; ++z) {
                        const auto zi = static_cast<Eigen::Index>(z);
                        const double sd = std::sqrt(scatter.variance(z, std::abs(q[z].q_total_w_m2)));
                        const double shared = loadings(zi, 0) * eta_air + loadings(zi, 1) * eta_rh + loadings(zi, 2) * eta_wall;
                        t.q_w_m2[z] = q[z].q_total_w_m2 * (1.0 + gain) + offset + shared + sd * unit(rng);
                        c.q_exp_w_m2[z] += t.q_w_m2[z] / replicates;
                    }
                    sum.air_temp_c += t.conditions.air_temp_c / replicates;
                    sum.air_rh_pct += t.conditions.air_rh_pct / replicates;
                    if (sum.wall_temp_c) *sum.wall_temp_c += *t.conditions.wall_temp_c / replicates;
                    for (std::size_t z = 0; z < z_count; ++z) sum.zones[z].skin_temp_c += t.conditions.zones[z].skin_temp_c / replicates;
                    c.trials.push_back(std::move(t));
                }
                c.conditions = std::move(sum);
                // The analysis's U shrinks with the replicates as its Type A part does (used for
                // locating and the points outside their CI, not for the claims).
                for (double& u : c.expanded_u_w_m2) u *= 1.0 / (here * std::sqrt(static_cast<double>(replicates)));
                // The points the recorded campaign leaves out (still drifting) are out of its draws too.
                for (std::size_t z = 0; z < z_count; ++z)
                    if (still_drifting(in, z)) c.q_exp_w_m2[z] = std::numeric_limits<double>::quiet_NaN();
                out.push_back(std::move(c));
            }
            return make_twin_model(std::move(out), model_.base_, model_.carried_);
        }

    private:
        const TwinModel& model_;
        NoiseParts parts_;
        ScatterModel scatter_;
        Instruments instruments_;
        double phi_ = 1.0;
        double s_air_ = 0.0, s_rh_ = 0.0, s_wall_ = 0.0;
        std::vector<double> s_skin_;
        InstrumentSpec flux_;  // the manikin's flux calibration: offset and gain
    };

    std::unique_ptr<CampaignSimulator> campaign_simulator(const Instruments& instruments, double shared_fraction) const override {
        if (cases_.empty()) return nullptr;
        NoiseParts parts = noise_parts(instruments, shared_fraction, {});
        ScatterModel scatter = scatter_of(estimate_scatter(parts.data));
        if (!scatter.estimable) return nullptr;
        return std::make_unique<Simulator>(*this, std::move(parts), std::move(scatter), instruments, shared_fraction);
    }

    // For `--noise-from`: this campaign's own scatter and how its estimate scatters.
    CarriedNoise carry(const Instruments& instruments, std::string source) const {
        NoiseParts parts = noise_parts(instruments, 0.5, {});
        const ScatterModel own = estimate_scatter(parts.data);
        if (!own.estimable)
            throw std::invalid_argument(source + ": no case has two replicates, so it has no replicate scatter to carry");
        std::vector<int> zone_ids;
        for (const auto& z : first_zones()) zone_ids.push_back(z.zone);
        auto to_carried = [zone_ids, source](const ScatterModel& s) {
            CarriedNoise c;
            c.source = source;
            c.relative_sd = s.relative_sd;
            c.factor_sd = s.factor_sd;
            c.dof = s.dof;
            for (std::size_t z = 0; z < zone_ids.size() && z < s.zone_sd_w_m2.size(); ++z) c.zone_sd_w_m2[zone_ids[z]] = s.zone_sd_w_m2[z];
            return c;
        };
        CarriedNoise out = to_carried(own);
        auto data = std::make_shared<const ReplicateResiduals>(parts.data);
        out.redraw = [data, own, to_carried](std::uint64_t seed) { return to_carried(estimate_scatter(simulate_residuals(*data, own, seed))); };
        return out;
    }

    void set_carried(std::optional<CarriedNoise> c) { carried_ = std::move(c); }
    const std::vector<tw::ZoneInput>& first_zones() const {
        static const std::vector<tw::ZoneInput> none;
        return cases_.empty() ? none : cases_.front().conditions.zones;
    }

private:
    std::vector<CaseInput> cases_;
    tw::TwinVersion base_;
    std::optional<CarriedNoise> carried_;
    std::vector<Point> points_;
    std::vector<std::string> measurement_;
    std::vector<std::pair<std::size_t, std::size_t>> index_;
    TrialFluxes base_flux_;  // the twin as given
    // Tells this model's kept fluxes from another's (a thread's memo outlives the models it served).
    std::uint64_t id_ = next_id();
    static std::uint64_t next_id() {
        static std::atomic<std::uint64_t> counter{0};
        return ++counter;
    }
};

class WholeBodyHModel final : public ForwardModel {
public:
    WholeBodyHModel(std::vector<HObservation> obs, double a, double exponent) : a_(a), exponent_(exponent) {
        for (const auto& o : obs) {
            Point p;
            p.case_id = o.case_id;
            p.zone_name = "whole body";
            p.region = "whole_body";
            p.q_exp = o.h_w_m2k;
            p.expanded_u = o.expanded_u_w_m2k;
            p.coverage_k = o.coverage_k;
            const double c_air = physics::vapour_concentration_kg_m3(physics::vapour_pressure_pa(o.air_temp_c, o.air_rh_pct), o.air_temp_c);
            dt_.push_back(o.skin_temp_c - o.air_temp_c);
            dc_.push_back(physics::saturation_concentration_kg_m3(o.skin_temp_c) - c_air);
            p.drivers["skin-air temperature difference"] = dt_.back();
            p.drivers["vapour concentration difference"] = dc_.back();
            p.drivers["relative humidity"] = o.air_rh_pct;
            points_.push_back(std::move(p));
        }
    }
    const std::vector<Point>& points() const override { return points_; }
    bool supports(const std::string& term) const override {
        return term == "humidity_buoyancy" || term == "diffusion_floor";
    }
    std::string base_name() const override { return fmt::format("h = {} |dT|^{}", a_, exponent_); }
    std::vector<tw::Term> base_terms() const override { return {}; }
    std::vector<double> predict(const std::vector<tw::Term>& extra) const override {
        double gamma = 0.0, h0 = 0.0;
        for (const auto& t : extra) {
            if (t.name == "humidity_buoyancy") gamma = t.parameters.at("gamma");
            else if (t.name == "diffusion_floor") h0 = t.parameters.at("h0");
            else throw std::invalid_argument("whole-body h model does not support " + t.name);
        }
        std::vector<double> out(points_.size());
        for (std::size_t i = 0; i < points_.size(); ++i)
            out[i] = h0 + a_ * std::pow(std::abs(dt_[i] + gamma * dc_[i]), exponent_);
        return out;
    }
    // Each CFD case stands alone: independent errors of the stated size, no replicates.
    NoiseModel noise_model(const Instruments&, double, const std::vector<tw::Term>&) const override {
        NoiseModel out;
        const auto n = static_cast<Eigen::Index>(points_.size());
        out.random_covariance = Eigen::MatrixXd::Zero(n, n);
        for (Eigen::Index i = 0; i < n; ++i) {
            const double u = points_[static_cast<std::size_t>(i)].standard_u();
            out.random_covariance(i, i) = u * u;
        }
        out.covariance = out.random_covariance;
        out.point_replicates.assign(points_.size(), 1);
        out.notes.push_back("independent observations with their stated standard uncertainty");
        return out;
    }

private:
    double a_, exponent_;
    std::vector<Point> points_;
    std::vector<double> dt_, dc_;
};

}  // namespace

std::unique_ptr<ForwardModel> make_twin_model(std::vector<CaseInput> cases, tw::TwinVersion base, std::optional<CarriedNoise> carried) {
    auto m = std::make_unique<TwinModel>(std::move(cases), std::move(base));
    m->set_carried(std::move(carried));
    return m;
}

CarriedNoise carried_noise(const ForwardModel& twin_model, const Instruments& instruments, std::string source) {
    const auto* twin = dynamic_cast<const TwinModel*>(&twin_model);
    if (!twin) throw std::invalid_argument("--noise-from needs a campaign of zone fluxes");
    return twin->carry(instruments, std::move(source));
}

std::unique_ptr<ForwardModel> make_whole_body_h_model(std::vector<HObservation> obs, double a, double exponent) {
    return std::make_unique<WholeBodyHModel>(std::move(obs), a, exponent);
}

}  // namespace manikind::analysis::reconcile
