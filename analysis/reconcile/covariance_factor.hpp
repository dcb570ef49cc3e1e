#pragma once
// The Cholesky factor L of the noise covariance C = L Lᵀ, kept in the covariance's own structure
// where it has one: blocks (one per case, the trial scatter and the case's share of the probes'
// Type B) plus a few directions shared by every point (the probes' common calibration, the
// manikin's offset and gain), C = D + U Uᵀ with D block diagonal. Then L is block lower
// triangular with L_ij = U_i S_j below the diagonal (block Cholesky: S_j = G_j U_jᵀ L_jj⁻ᵀ,
// G_1 = I, G_j+1 = G_j - S_j S_jᵀ), which is the same factor as the dense one, so whitened
// vectors are the same to rounding, at about a tenth of the cost of the dense triangular solve
// (docs/notes/reconcile-history.md, "Issue 62"). Without that structure: the dense factor.
#include <vector>

#include <Eigen/Cholesky>
#include <Eigen/Core>

namespace manikind::analysis::reconcile::evidence {

class CovarianceFactor {
public:
    CovarianceFactor() = default;
    // `block_of[i]`: point i's block (its case); blocks are the runs of equal values in point
    // order. `shared` (n x g, may be null or empty): C - shared sharedᵀ must vanish between blocks
    // (checked; otherwise the dense factor). Throws std::runtime_error when C is not positive definite.
    CovarianceFactor(const Eigen::MatrixXd& covariance, const std::vector<int>& block_of, const Eigen::MatrixXd* shared);

    Eigen::Index size() const { return n_; }
    bool structured() const { return !blocks_.empty(); }

    void solve_lower_in_place(Eigen::MatrixXd& x) const;   // x := L⁻¹ x
    void solve_lower_in_place(Eigen::VectorXd& x) const;
    Eigen::MatrixXd lower_times(const Eigen::MatrixXd& x) const;  // L x
    Eigen::MatrixXd upper_times(const Eigen::MatrixXd& x) const;  // Lᵀ x

private:
    struct Block {
        Eigen::Index start = 0, size = 0;
        Eigen::MatrixXd l;   // L_jj, lower triangular
        Eigen::MatrixXd u;   // U_j (size x g)
        Eigen::MatrixXd s;   // S_j (g x size)
    };
    template <class M>
    void solve_in_place(M& x) const;

    Eigen::Index n_ = 0;
    Eigen::Index g_ = 0;
    std::vector<Block> blocks_;         // structured
    Eigen::LLT<Eigen::MatrixXd> dense_; // otherwise
};

}  // namespace manikind::analysis::reconcile::evidence
