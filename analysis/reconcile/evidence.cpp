#include "analysis/reconcile/evidence.hpp"

#include <algorithm>
#include <cmath>
#include <future>
#include <limits>
#include <map>
#include <set>
#include <stdexcept>

#include <Eigen/Dense>
#include <fmt/core.h>

#include "analysis/reconcile/least_squares.hpp"

namespace manikind::analysis::reconcile::evidence {
namespace tw = physics::twin;
namespace {

}  // namespace

Eigen::VectorXd Subset::select(const std::vector<double>& v) const {
    Eigen::VectorXd out(size());
    for (Eigen::Index i = 0; i < size(); ++i) out(i) = v[idx[static_cast<std::size_t>(i)]];
    return out;
}

Eigen::VectorXd Subset::whiten(const std::vector<double>& v) const {
    Eigen::VectorXd out = select(v);
    factor.solve_lower_in_place(out);
    return out;
}

double Subset::chi2(const std::vector<double>& prediction) const { return (y - whiten(prediction)).squaredNorm(); }

Eigen::MatrixXd restrict_to(const Eigen::MatrixXd& covariance, const std::vector<std::size_t>& idx) {
    const auto n = static_cast<Eigen::Index>(idx.size());
    Eigen::MatrixXd sub(n, n);
    for (Eigen::Index a = 0; a < n; ++a)
        for (Eigen::Index b = 0; b < n; ++b)
            sub(a, b) = covariance(static_cast<Eigen::Index>(idx[static_cast<std::size_t>(a)]),
                                   static_cast<Eigen::Index>(idx[static_cast<std::size_t>(b)]));
    return sub;
}

Subset make_subset(const ForwardModel& model, const Eigen::MatrixXd& covariance, std::vector<std::size_t> idx,
                   const std::vector<double>& base_prediction, const Eigen::MatrixXd* shared) {
    Subset s;
    s.idx = std::move(idx);
    const auto& pts = model.points();
    const Eigen::Index n = s.size();
    const Eigen::MatrixXd sub = restrict_to(covariance, s.idx);
    std::vector<int> case_of(s.idx.size());
    for (std::size_t i = 0; i < s.idx.size(); ++i) case_of[i] = pts[s.idx[i]].case_id;
    Eigen::MatrixXd shared_rows;
    if (shared && shared->rows() == static_cast<Eigen::Index>(pts.size())) {
        shared_rows.resize(n, shared->cols());
        for (Eigen::Index i = 0; i < n; ++i) shared_rows.row(i) = shared->row(static_cast<Eigen::Index>(s.idx[static_cast<std::size_t>(i)]));
    }
    s.factor = CovarianceFactor(sub, case_of, shared_rows.size() > 0 ? &shared_rows : nullptr);
    std::map<int, std::size_t> case_pos;
    for (Eigen::Index i = 0; i < n; ++i) {
        const int id = pts[s.idx[static_cast<std::size_t>(i)]].case_id;
        auto [it, fresh] = case_pos.emplace(id, s.case_ids.size());
        if (fresh) {
            s.case_ids.push_back(id);
            s.case_rows.emplace_back();
        }
        s.case_rows[it->second].push_back(i);
    }
    for (const auto& rows : s.case_rows) {
        const auto m = static_cast<Eigen::Index>(rows.size());
        Eigen::MatrixXd block(m, m);
        for (Eigen::Index a = 0; a < m; ++a)
            for (Eigen::Index b = 0; b < m; ++b) block(a, b) = sub(rows[static_cast<std::size_t>(a)], rows[static_cast<std::size_t>(b)]);
        s.case_llt.emplace_back(block);
    }
    std::vector<double> q(pts.size());
    for (std::size_t i = 0; i < pts.size(); ++i) q[i] = pts[i].q_exp;
    s.y = s.whiten(q);
    s.w_base = s.whiten(base_prediction);
    return s;
}

Grid make_grid(const ForwardModel& model, const CandidateTerm& term, int steps) {
    Grid g;
    g.term = term;
    const auto& p = term.parameters.at(0);
    for (int i = 0; i <= steps; ++i) g.theta.push_back(p.lo + (p.hi - p.lo) * i / steps);
    g.raw.resize(g.theta.size());
    g.valid.assign(g.theta.size(), true);
    for (std::size_t i = 0; i < g.theta.size(); ++i) {
        try {
            g.raw[i] = model.predict(to_twin_terms({term}, {g.theta[i]}));
            for (double v : g.raw[i])
                if (!std::isfinite(v)) g.valid[i] = false;
        } catch (const std::exception&) {
            g.valid[i] = false;  // a parameter the physics cannot evaluate is never the best
        }
        if (!g.valid[i]) g.raw[i].assign(model.points().size(), 0.0);
    }
    return g;
}

std::vector<CandidateTerm> single_library(const ForwardModel& model, const std::string& generated) {
    std::set<std::string> wet_regions;
    // What the zones' geometry can show (the drivers TwinModel gives each point).
    std::set<double> heights;
    std::set<double> sides, facings;
    bool air_moves = false;
    for (const auto& p : model.points()) {
        // Air that moves (over 0.05 m/s, beyond a sealed enclosure's < 0.02: Text S3.1) in some case.
        if (const auto v = p.drivers.find("air speed"); v != p.drivers.end() && v->second > 0.05) air_moves = true;
        const auto it = p.drivers.find("wettedness");
        if (it != p.drivers.end() && it->second > 0.0) wet_regions.insert(p.region);
        if (const auto h = p.drivers.find("zone height"); h != p.drivers.end()) heights.insert(h->second);
        if (const auto sd = p.drivers.find("side (left -1, right +1)"); sd != p.drivers.end()) sides.insert(sd->second);
        if (const auto f = p.drivers.find("facing (back -1, front +1)"); f != p.drivers.end()) facings.insert(f->second);
    }
    std::vector<CandidateTerm> library;
    for (auto& c : candidate_library({wet_regions.begin(), wet_regions.end()}))
        if (model.supports(c.term) && c.parameters.size() == 1) library.push_back(std::move(c));
    if (generated != "none" && model.supports("input_pattern")) {
        GeometryKnown g;
        g.height = heights.size() > 1;
        g.sides = sides.count(-1.0) && sides.count(1.0);
        g.facing = facings.count(-1.0) && facings.count(1.0);
        g.wet = !wet_regions.empty();
        g.air_moves = air_moves;
        for (auto& c : generated_hypotheses(g, generated == "all")) library.push_back(std::move(c));
    }
    return library;
}

std::vector<Grid> make_grids(const ForwardModel& model, const std::vector<CandidateTerm>& library, int steps) {
    std::vector<Grid> grids(library.size());
    auto work = [&](std::size_t begin) {
        for (std::size_t k = begin; k < library.size(); k += 2) grids[k] = make_grid(model, library[k], steps);
    };
    auto other = std::async(std::launch::async, work, 1);
    work(0);
    other.get();
    return grids;
}

WhitenedGrid whiten_grid(const Subset& s, const Grid& g) {
    WhitenedGrid out;
    out.grid = &g;
    const auto cols = static_cast<Eigen::Index>(g.theta.size());
    Eigen::MatrixXd raw(s.size(), cols);
    for (Eigen::Index c = 0; c < cols; ++c) raw.col(c) = s.select(g.raw[static_cast<std::size_t>(c)]);
    s.factor.solve_lower_in_place(raw);
    out.w = std::move(raw);
    out.norm2 = out.w.colwise().squaredNorm().transpose();
    return out;
}

ProfileMin profile_min(const Eigen::Ref<const Eigen::VectorXd>& chi2, const Grid& g) {
    const auto n = chi2.size();
    Eigen::Index best = -1;
    for (Eigen::Index i = 0; i < n; ++i)
        if (g.valid[static_cast<std::size_t>(i)] && (best < 0 || chi2(i) < chi2(best))) best = i;
    ProfileMin out;
    if (best < 0) {
        out.chi2 = std::numeric_limits<double>::infinity();
        return out;
    }
    out.chi2 = chi2(best);
    out.grid_chi2 = out.chi2;
    out.theta = g.theta[static_cast<std::size_t>(best)];
    if (best > 0 && best + 1 < n && g.valid[static_cast<std::size_t>(best - 1)] && g.valid[static_cast<std::size_t>(best + 1)]) {
        const double a = chi2(best - 1), b = chi2(best), d = chi2(best + 1);
        const double curvature = a - 2.0 * b + d;
        if (curvature > 0.0) {
            const double x = std::clamp((a - d) / (2.0 * curvature), -1.0, 1.0);
            out.chi2 = std::min(b, b - (d - a) * (d - a) / (8.0 * curvature));
            const double step = g.theta[1] - g.theta[0];
            out.theta += x * step;
            out.curvature = curvature / (step * step);
        }
    }
    return out;
}

Eigen::MatrixXd profile_chi2(const std::vector<const WhitenedGrid*>& grids, const Eigen::MatrixXd& y) {
    const auto k_count = static_cast<Eigen::Index>(grids.size());
    Eigen::MatrixXd out(k_count, y.cols());
    const Eigen::RowVectorXd y_norm2 = y.colwise().squaredNorm();
    auto work = [&](Eigen::Index begin, Eigen::Index end) {
        for (Eigen::Index k = 0; k < k_count; ++k) {
            const auto& wg = *grids[static_cast<std::size_t>(k)];
            const Eigen::MatrixXd cross = wg.w.transpose() * y.middleCols(begin, end - begin);  // G x B
            Eigen::VectorXd chi2(cross.rows());
            for (Eigen::Index b = 0; b < cross.cols(); ++b) {
                chi2 = (wg.norm2 - 2.0 * cross.col(b)).array() + y_norm2(begin + b);
                out(k, begin + b) = profile_min(chi2, *wg.grid).chi2;
            }
        }
    };
    const Eigen::Index half = y.cols() / 2;
    if (half >= 32) {  // two cores: split the simulated campaigns
        auto other = std::async(std::launch::async, work, half, y.cols());
        work(0, half);
        other.get();
    } else {
        work(0, y.cols());
    }
    return out;
}

Eigen::MatrixXd simulate(const Eigen::VectorXd& mean, int count, std::mt19937_64& rng) {
    std::normal_distribution<double> normal(0.0, 1.0);
    Eigen::MatrixXd y(mean.size(), count);
    for (Eigen::Index b = 0; b < count; ++b)
        for (Eigen::Index i = 0; i < mean.size(); ++i) y(i, b) = mean(i) + normal(rng);
    return y;
}

Eigen::MatrixXd local_directions(const ForwardModel& model, const Subset& s, const std::vector<double>& base_pred,
                                 std::vector<std::pair<int, bool>>* kinds) {
    const auto& pts = model.points();
    std::map<int, Eigen::Index> column;
    std::vector<int> zones;
    for (std::size_t i : s.idx)
        if (column.emplace(pts[i].zone, static_cast<Eigen::Index>(zones.size())).second) zones.push_back(pts[i].zone);
    const auto z_count = static_cast<Eigen::Index>(zones.size());
    Eigen::MatrixXd a = Eigen::MatrixXd::Zero(s.size(), 2 * z_count);
    for (Eigen::Index i = 0; i < s.size(); ++i) {
        const std::size_t point = s.idx[static_cast<std::size_t>(i)];
        const Eigen::Index z = column[pts[point].zone];
        a(i, 2 * z) = 1.0;
        a(i, 2 * z + 1) = base_pred[point];
    }
    if (kinds) {
        kinds->clear();
        for (int z : zones) {
            kinds->emplace_back(z, false);
            kinds->emplace_back(z, true);
        }
    }
    s.factor.solve_lower_in_place(a);
    return a;
}

Eigen::VectorXd linear_evidence(const Eigen::MatrixXd& directions, const Eigen::VectorXd& r) {
    Eigen::VectorXd out(directions.cols());
    for (Eigen::Index j = 0; j < directions.cols(); ++j) {
        const double info = directions.col(j).squaredNorm();
        out(j) = info > 1e-12 ? std::pow(directions.col(j).dot(r), 2) / info : 0.0;
    }
    return out;
}

namespace {

constexpr double kShiftCap = 16.0;      // whitened norm: beyond, a shift is 8 sd from being preferred
constexpr double kBasisTolerance = 0.02; // largest column left out of the basis, whitened units
constexpr int kCampaignsPerDraw = 50;

// Columns of the grids near the twin and the linear directions, in an orthonormal basis found by
// pivoted Gram-Schmidt (stops when every column is represented within kBasisTolerance).
struct ShiftBasis {
    Eigen::MatrixXd u;                        // n x r
    Eigen::MatrixXd grid_coef;                // r x m, the kept grid columns
    std::vector<std::pair<std::size_t, Eigen::Index>> grid_column;  // (grid, grid point) per kept column
    Eigen::MatrixXd linear_coef;              // r x L, unit directions
};

ShiftBasis shift_basis(const Subset& s, const std::vector<WhitenedGrid>& grids, const Eigen::MatrixXd& linear) {
    ShiftBasis out;
    std::vector<Eigen::VectorXd> cols;
    for (std::size_t k = 0; k < grids.size(); ++k) {
        const auto& wg = grids[k];
        for (Eigen::Index g = 0; g < wg.w.cols(); ++g) {
            if (!wg.grid->valid[static_cast<std::size_t>(g)]) continue;
            Eigen::VectorXd d = wg.w.col(g) - s.w_base;
            if (d.norm() > kShiftCap) continue;
            out.grid_column.emplace_back(k, g);
            cols.push_back(std::move(d));
        }
    }
    const auto m = static_cast<Eigen::Index>(cols.size());
    Eigen::MatrixXd d(s.size(), m + linear.cols());
    for (Eigen::Index j = 0; j < m; ++j) d.col(j) = cols[static_cast<std::size_t>(j)];
    for (Eigen::Index j = 0; j < linear.cols(); ++j) {
        const double norm = linear.col(j).norm();
        d.col(m + j) = norm > 0.0 ? Eigen::VectorXd(linear.col(j) / norm) : Eigen::VectorXd::Zero(s.size());
    }
    Eigen::MatrixXd resid = d;
    std::vector<Eigen::VectorXd> basis;
    while (static_cast<Eigen::Index>(basis.size()) < s.size()) {
        Eigen::Index best = -1;
        double best_norm = kBasisTolerance;
        for (Eigen::Index j = 0; j < resid.cols(); ++j) {
            const double v = resid.col(j).norm();
            if (v > best_norm) {
                best_norm = v;
                best = j;
            }
        }
        if (best < 0) break;
        Eigen::VectorXd q = resid.col(best) / best_norm;
        for (const auto& b : basis) q -= b.dot(q) * b;  // once more against round-off
        q.normalize();
        resid -= q * (q.transpose() * resid);
        basis.push_back(std::move(q));
    }
    out.u.resize(s.size(), static_cast<Eigen::Index>(basis.size()));
    for (std::size_t i = 0; i < basis.size(); ++i) out.u.col(static_cast<Eigen::Index>(i)) = basis[i];
    const Eigen::MatrixXd coef = out.u.transpose() * d;
    out.grid_coef = coef.leftCols(m);
    out.linear_coef = coef.rightCols(linear.cols());
    return out;
}

}  // namespace

FamilyNull family_null(const Subset& s, const std::vector<WhitenedGrid>& grids, const Eigen::MatrixXd& linear,
                       const std::function<Eigen::MatrixXd(std::uint64_t)>& draw_covariance, int simulations,
                       std::uint64_t seed) {
    FamilyNull out;
    const ShiftBasis sb = shift_basis(s, grids, linear);
    out.basis_rank = static_cast<int>(sb.u.cols());
    const int draws = draw_covariance ? std::max(1, simulations / kCampaignsPerDraw) : 1;
    const int per_draw = draw_covariance ? kCampaignsPerDraw : simulations;
    out.covariance_draws = draw_covariance ? draws : 0;
    out.max_evidence.assign(static_cast<std::size_t>(draws * per_draw), 0.0);
    out.max_evidence_at_points.assign(out.max_evidence.size(), 0.0);
    out.chi2.assign(out.max_evidence.size(), 0.0);
    // Judged under a covariance S* the whitened shift d and data z (z ~ N(0, I): the fitted model
    // is the truth) give chi2 reductions 2 d'Qz - d'Qd with Q = L' S*^-1 L (L the fitted
    // model's factor); with d = U c, that is 2 c'(QU)'z - c'(U'QU)c.
    auto one_draw = [&](int b) {
        Eigen::MatrixXd qu = sb.u;
        std::mt19937_64 rng(seed + 104729ULL * static_cast<std::uint64_t>(b + 1));
        const Eigen::MatrixXd z = simulate(Eigen::VectorXd::Zero(s.size()), per_draw, rng);
        Eigen::RowVectorXd chi2;
        if (draw_covariance) {
            const Eigen::MatrixXd cov = draw_covariance(seed + 7919ULL * static_cast<std::uint64_t>(b + 1));
            Eigen::LLT<Eigen::MatrixXd> llt(cov);
            if (llt.info() != Eigen::Success) return false;
            const Eigen::MatrixXd lu = s.factor.lower_times(sb.u);
            qu = s.factor.upper_times(llt.solve(lu));
            // The twin's own chi2 judged by the drawn covariance: z'Qz = |L*^-1 L z|².
            const Eigen::MatrixXd lz = s.factor.lower_times(z);
            chi2 = llt.matrixL().solve(lz).colwise().squaredNorm();
        } else {
            chi2 = z.colwise().squaredNorm();
        }
        const Eigen::MatrixXd g = sb.u.transpose() * qu;
        const Eigen::RowVectorXd quad = (sb.grid_coef.array() * (g * sb.grid_coef).array()).colwise().sum();
        const Eigen::RowVectorXd lin_info = (sb.linear_coef.array() * (g * sb.linear_coef).array()).colwise().sum();
        const Eigen::MatrixXd p = qu.transpose() * z;                     // r x S
        const Eigen::MatrixXd e_grid = 2.0 * (sb.grid_coef.transpose() * p);  // m x S, before the quadratic
        const Eigen::MatrixXd e_lin = sb.linear_coef.transpose() * p;     // L x S
        for (Eigen::Index c = 0; c < per_draw; ++c) {
            double best = 0.0, best_point = 0.0;
            const auto& gc = sb.grid_column;
            for (std::size_t j = 0; j < gc.size(); ++j) {
                const double e = e_grid(static_cast<Eigen::Index>(j), c) - quad(static_cast<Eigen::Index>(j));
                best_point = std::max(best_point, e);
                if (e <= best) continue;
                double refined = e;
                // The parabola through the neighbours, as profile_min refines the observed.
                const bool left = j > 0 && gc[j - 1].first == gc[j].first && gc[j - 1].second + 1 == gc[j].second;
                const bool right = j + 1 < gc.size() && gc[j + 1].first == gc[j].first && gc[j + 1].second == gc[j].second + 1;
                if (left && right) {
                    const double a = e_grid(static_cast<Eigen::Index>(j - 1), c) - quad(static_cast<Eigen::Index>(j - 1));
                    const double d = e_grid(static_cast<Eigen::Index>(j + 1), c) - quad(static_cast<Eigen::Index>(j + 1));
                    const double curvature = 2.0 * e - a - d;
                    if (a <= e && d <= e && curvature > 0.0) refined = e + (d - a) * (d - a) / (8.0 * curvature);
                }
                best = std::max(best, refined);
            }
            for (Eigen::Index j = 0; j < e_lin.rows(); ++j)
                if (lin_info(j) > 1e-12) {
                    best = std::max(best, e_lin(j, c) * e_lin(j, c) / lin_info(j));
                    best_point = std::max(best_point, e_lin(j, c) * e_lin(j, c) / lin_info(j));
                }
            out.max_evidence[static_cast<std::size_t>(b * per_draw + c)] = best;
            out.max_evidence_at_points[static_cast<std::size_t>(b * per_draw + c)] = best_point;
            out.chi2[static_cast<std::size_t>(b * per_draw + c)] = chi2(c);
        }
        return true;
    };
    std::vector<char> ok(static_cast<std::size_t>(draws), 0);
    auto work = [&](int begin) {
        for (int b = begin; b < draws; b += 2) ok[static_cast<std::size_t>(b)] = one_draw(b) ? 1 : 0;
    };
    if (draws > 1) {
        auto other = std::async(std::launch::async, work, 1);
        work(0);
        other.get();
    } else {
        work(0);
    }
    // A draw whose covariance was not positive definite is left out (never counted as zero).
    std::vector<double> kept, kept_points, kept_chi2;
    for (int b = 0; b < draws; ++b)
        if (ok[static_cast<std::size_t>(b)]) {
            kept.insert(kept.end(), out.max_evidence.begin() + b * per_draw, out.max_evidence.begin() + (b + 1) * per_draw);
            kept_points.insert(kept_points.end(), out.max_evidence_at_points.begin() + b * per_draw,
                               out.max_evidence_at_points.begin() + (b + 1) * per_draw);
            kept_chi2.insert(kept_chi2.end(), out.chi2.begin() + b * per_draw, out.chi2.begin() + (b + 1) * per_draw);
        }
    out.max_evidence = std::move(kept);
    out.max_evidence_at_points = std::move(kept_points);
    out.chi2 = std::move(kept_chi2);
    return out;
}

double upper_quantile(std::vector<double> sample, double alpha) {
    if (sample.empty()) return std::numeric_limits<double>::infinity();
    std::sort(sample.begin(), sample.end());
    const double pos = (1.0 - alpha) * static_cast<double>(sample.size() - 1);
    const auto lo = static_cast<std::size_t>(std::floor(pos));
    const std::size_t hi = std::min(lo + 1, sample.size() - 1);
    return sample[lo] + (pos - static_cast<double>(lo)) * (sample[hi] - sample[lo]);
}

CaseLevel case_level(const ForwardModel& model, const Subset& s, const std::vector<CandidateTerm>& terms,
                     const std::vector<double>& theta) {
    const auto& pts = model.points();
    std::vector<Bounds> bounds;
    for (const auto& t : terms)
        for (const auto& p : t.parameters) bounds.push_back({p.lo, p.hi});
    const auto p_count = static_cast<Eigen::Index>(theta.size());
    const auto f0 = model.predict(to_twin_terms(terms, theta));
    std::vector<std::vector<double>> df(theta.size());
    std::vector<double> steps(theta.size());
    // Secant over 1/120 of the range (the grid step), stepping inward at a bound: the same finite
    // step as the fit's covariance, for the same reason (the kink at dT = 0).
    for (std::size_t j = 0; j < theta.size(); ++j) {
        double h = (bounds[j].hi - bounds[j].lo) / 120.0;
        if (theta[j] + h > bounds[j].hi) h = -h;
        auto t = theta;
        t[j] += h;
        df[j] = model.predict(to_twin_terms(terms, t));
        steps[j] = h;
    }
    CaseLevel out;
    const auto cases = s.case_rows.size();
    std::vector<Eigen::VectorXd> r(cases);          // whitened residual per case
    std::vector<Eigen::MatrixXd> d(cases);          // whitened derivative of the prediction
    std::vector<Eigen::VectorXd> raw_r(cases);
    std::vector<Eigen::MatrixXd> raw_d(cases);
    Eigen::MatrixXd a_total = Eigen::MatrixXd::Zero(p_count, p_count);
    Eigen::VectorXd g_total = Eigen::VectorXd::Zero(p_count);
    std::vector<Eigen::MatrixXd> a_case(cases);
    std::vector<Eigen::VectorXd> g_case(cases);
    for (std::size_t c = 0; c < cases; ++c) {
        const auto& rows = s.case_rows[c];
        const auto m = static_cast<Eigen::Index>(rows.size());
        raw_r[c].resize(m);
        raw_d[c].resize(m, p_count);
        for (Eigen::Index i = 0; i < m; ++i) {
            const std::size_t point = s.idx[static_cast<std::size_t>(rows[static_cast<std::size_t>(i)])];
            raw_r[c](i) = pts[point].q_exp - f0[point];
            for (Eigen::Index j = 0; j < p_count; ++j)
                raw_d[c](i, j) = (df[static_cast<std::size_t>(j)][point] - f0[point]) / steps[static_cast<std::size_t>(j)];
        }
        r[c] = s.case_llt[c].matrixL().solve(raw_r[c]);
        d[c] = s.case_llt[c].matrixL().solve(raw_d[c]);
        a_case[c] = d[c].transpose() * d[c];
        g_case[c] = d[c].transpose() * r[c];
        a_total += a_case[c];
        g_total += g_case[c];
    }
    double sum_sq = 0.0;
    int count = 0;
    const Eigen::LDLT<Eigen::MatrixXd> tot(a_total);  // every held-out case's predictive score uses it
    for (std::size_t c = 0; c < cases; ++c) {
        Eigen::VectorXd delta = Eigen::VectorXd::Zero(p_count);
        if (p_count > 0 && cases > 1) {
            delta = (a_total - a_case[c]).ldlt().solve(g_total - g_case[c]);
            for (Eigen::Index j = 0; j < p_count; ++j) {
                const auto& b = bounds[static_cast<std::size_t>(j)];
                const double t = theta[static_cast<std::size_t>(j)];
                delta(j) = std::clamp(t + delta(j), b.lo, b.hi) - t;
            }
        }
        const Eigen::VectorXd e = r[c] - d[c] * delta;
        if (p_count > 0 && cases > 1) {
            // Predictive score of the held-out case: its residual weighed by the covariance of
            // the rest's prediction, I + d A_rest^-1 d', plus that covariance's log det (the
            // Gaussian predictive deviance). By Woodbury this is e'e - (d'e)' A_tot^-1 (d'e)
            // + log det A_tot - log det A_rest. A case that alone carries a term's information
            // is then scored by how little the rest can say about it, not by how far the rest's
            // guess lands (a lab's probe error moves that guess; see docs/reconcile.md).
            const Eigen::VectorXd de = d[c].transpose() * e;
            const Eigen::MatrixXd shrink =
                Eigen::MatrixXd::Identity(p_count, p_count) - tot.solve(a_case[c]);  // A_tot^-1 A_rest
            const double det_ratio = std::max(shrink.determinant(), std::numeric_limits<double>::min());
            out.loo_score += e.squaredNorm() - de.dot(tot.solve(de)) - std::log(det_ratio);
        } else {
            out.loo_score += e.squaredNorm();
        }
        const Eigen::VectorXd raw_e = raw_r[c] - raw_d[c] * delta;
        sum_sq += raw_e.squaredNorm();
        count += static_cast<int>(raw_e.size());
    }
    out.loo_rmse = count > 0 ? std::sqrt(sum_sq / count) : 0.0;
    out.robust_se.assign(theta.size(), std::numeric_limits<double>::infinity());
    const auto c_count = static_cast<double>(cases);
    if (p_count > 0 && c_count > static_cast<double>(p_count)) {
        Eigen::MatrixXd meat = Eigen::MatrixXd::Zero(p_count, p_count);
        const Eigen::VectorXd g_mean = g_total / c_count;
        for (std::size_t c = 0; c < cases; ++c) {
            const Eigen::VectorXd g = g_case[c] - g_mean;
            meat += g * g.transpose();
        }
        Eigen::FullPivLU<Eigen::MatrixXd> lu(a_total);
        if (lu.isInvertible()) {
            const Eigen::MatrixXd bread = lu.inverse();
            const Eigen::MatrixXd v = bread * meat * bread * (c_count / (c_count - static_cast<double>(p_count)));
            for (Eigen::Index j = 0; j < p_count; ++j) out.robust_se[static_cast<std::size_t>(j)] = std::sqrt(std::max(0.0, v(j, j)));
        }
    }
    return out;
}

}  // namespace manikind::analysis::reconcile::evidence
