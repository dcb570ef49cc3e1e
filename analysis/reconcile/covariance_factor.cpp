#include "analysis/reconcile/covariance_factor.hpp"

#include <algorithm>
#include <cmath>
#include <stdexcept>

#include <Eigen/Dense>

namespace manikind::analysis::reconcile::evidence {
namespace {

constexpr const char* kNotPositive = "reconcile: the noise covariance is not positive definite";

// Between blocks the covariance must be the shared part alone, to rounding: a covariance built
// otherwise (a term added between two cases) takes the dense factor.
bool shared_between_blocks(const Eigen::MatrixXd& c, const Eigen::MatrixXd& u, const std::vector<Eigen::Index>& starts) {
    const double scale = std::max(c.diagonal().cwiseAbs().maxCoeff(), 1e-300);
    const auto m = starts.size() - 1;
    for (std::size_t i = 0; i < m; ++i)
        for (std::size_t j = 0; j < i; ++j) {
            const Eigen::Index ri = starts[i], ni = starts[i + 1] - starts[i];
            const Eigen::Index rj = starts[j], nj = starts[j + 1] - starts[j];
            const Eigen::MatrixXd outside = c.block(ri, rj, ni, nj) - u.middleRows(ri, ni) * u.middleRows(rj, nj).transpose();
            if (outside.cwiseAbs().maxCoeff() > 1e-10 * scale) return false;
        }
    return true;
}

}  // namespace

CovarianceFactor::CovarianceFactor(const Eigen::MatrixXd& c, const std::vector<int>& block_of, const Eigen::MatrixXd* shared)
    : n_(c.rows()) {
    std::vector<Eigen::Index> starts;
    for (Eigen::Index i = 0; i < n_; ++i)
        if (i == 0 || block_of[static_cast<std::size_t>(i)] != block_of[static_cast<std::size_t>(i - 1)]) starts.push_back(i);
    starts.push_back(n_);
    const bool have_shared = shared && shared->rows() == n_;
    const Eigen::MatrixXd u = have_shared ? *shared : Eigen::MatrixXd(n_, 0);
    if (n_ > 0 && starts.size() > 2 && shared_between_blocks(c, u, starts)) {
        g_ = u.cols();
        Eigen::MatrixXd g = Eigen::MatrixXd::Identity(g_, g_);
        for (std::size_t k = 0; k + 1 < starts.size(); ++k) {
            Block b;
            b.start = starts[k];
            b.size = starts[k + 1] - starts[k];
            b.u = u.middleRows(b.start, b.size);
            // The block as left after the earlier blocks: C_jj - U_j (I - G_j) U_jᵀ.
            const Eigen::MatrixXd a = c.block(b.start, b.start, b.size, b.size) -
                                      b.u * (Eigen::MatrixXd::Identity(g_, g_) - g) * b.u.transpose();
            Eigen::LLT<Eigen::MatrixXd> llt(a);
            if (llt.info() != Eigen::Success) throw std::runtime_error(kNotPositive);
            b.l = llt.matrixL();
            // S_jᵀ = L_jj⁻¹ U_j G_j.
            Eigen::MatrixXd st = b.u * g;
            b.l.triangularView<Eigen::Lower>().solveInPlace(st);
            b.s = st.transpose();
            g -= b.s * st;
            blocks_.push_back(std::move(b));
        }
        return;
    }
    dense_.compute(c);
    if (dense_.info() != Eigen::Success) throw std::runtime_error(kNotPositive);
}

// Forward substitution by blocks: y_j = L_jj⁻¹ (x_j - U_j t_j), t_j = sum over k < j of S_k y_k.
template <class M>
void CovarianceFactor::solve_in_place(M& x) const {
    if (!structured()) {
        dense_.matrixL().solveInPlace(x);
        return;
    }
    Eigen::MatrixXd t = Eigen::MatrixXd::Zero(g_, x.cols());
    for (const auto& b : blocks_) {
        auto xj = x.middleRows(b.start, b.size);
        if (g_ > 0) xj.noalias() -= b.u * t;
        b.l.triangularView<Eigen::Lower>().solveInPlace(xj);
        if (g_ > 0) t.noalias() += b.s * xj;
    }
}

void CovarianceFactor::solve_lower_in_place(Eigen::MatrixXd& x) const { solve_in_place(x); }
void CovarianceFactor::solve_lower_in_place(Eigen::VectorXd& x) const { solve_in_place(x); }

Eigen::MatrixXd CovarianceFactor::lower_times(const Eigen::MatrixXd& x) const {
    if (!structured()) return dense_.matrixL() * x;
    Eigen::MatrixXd out(x.rows(), x.cols());
    Eigen::MatrixXd t = Eigen::MatrixXd::Zero(g_, x.cols());
    for (const auto& b : blocks_) {
        const auto xj = x.middleRows(b.start, b.size);
        out.middleRows(b.start, b.size).noalias() = b.l.triangularView<Eigen::Lower>() * xj;
        if (g_ > 0) {
            out.middleRows(b.start, b.size).noalias() += b.u * t;
            t.noalias() += b.s * xj;
        }
    }
    return out;
}

// (Lᵀ x)_j = L_jjᵀ x_j + S_jᵀ w_j, w_j = sum over i > j of U_iᵀ x_i.
Eigen::MatrixXd CovarianceFactor::upper_times(const Eigen::MatrixXd& x) const {
    if (!structured()) return dense_.matrixU() * x;
    Eigen::MatrixXd out(x.rows(), x.cols());
    Eigen::MatrixXd w = Eigen::MatrixXd::Zero(g_, x.cols());
    for (auto it = blocks_.rbegin(); it != blocks_.rend(); ++it) {
        const auto& b = *it;
        const auto xj = x.middleRows(b.start, b.size);
        out.middleRows(b.start, b.size).noalias() = b.l.transpose().triangularView<Eigen::Upper>() * xj;
        if (g_ > 0) {
            out.middleRows(b.start, b.size).noalias() += b.s.transpose() * w;
            w.noalias() += b.u.transpose() * xj;
        }
    }
    return out;
}

}  // namespace manikind::analysis::reconcile::evidence
