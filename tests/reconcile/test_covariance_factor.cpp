// The structured Cholesky factor of the noise covariance against the dense one (issue 62).
#include <random>
#include <stdexcept>

#include <Eigen/Dense>
#include <catch2/catch.hpp>

#include "analysis/reconcile/covariance_factor.hpp"

namespace cf_ev = manikind::analysis::reconcile::evidence;

namespace {

// A covariance of the reconcile's shape: per case a dense block (trial scatter and the case's
// share of the probes), plus g directions shared by every point.
struct CfShaped {
    Eigen::MatrixXd c, u;
    std::vector<int> block_of;
};

CfShaped cf_shaped(int cases, int zones, int g, unsigned seed) {
    std::mt19937_64 rng(seed);
    std::normal_distribution<double> n01;
    const int n = cases * zones;
    CfShaped out;
    out.c = Eigen::MatrixXd::Zero(n, n);
    out.u.resize(n, g);
    for (int i = 0; i < n; ++i)
        for (int k = 0; k < g; ++k) out.u(i, k) = n01(rng);
    for (int c = 0; c < cases; ++c) {
        Eigen::MatrixXd a(zones, zones + 3);
        for (int i = 0; i < a.rows(); ++i)
            for (int j = 0; j < a.cols(); ++j) a(i, j) = n01(rng);
        out.c.block(c * zones, c * zones, zones, zones) = a * a.transpose() / 10.0;
        for (int z = 0; z < zones; ++z) out.block_of.push_back(100 + c);
    }
    out.c += out.u * out.u.transpose();
    return out;
}

}  // namespace

TEST_CASE("the structured factor whitens, multiplies and transposes as the dense Cholesky factor does", "[reconcile]") {
    const CfShaped s = cf_shaped(7, 9, 5, 3);
    const cf_ev::CovarianceFactor f(s.c, s.block_of, &s.u);
    REQUIRE(f.structured());
    const Eigen::LLT<Eigen::MatrixXd> dense(s.c);
    const Eigen::MatrixXd l = dense.matrixL();

    std::mt19937_64 rng(11);
    std::normal_distribution<double> n01;
    Eigen::MatrixXd x(s.c.rows(), 4);
    for (Eigen::Index i = 0; i < x.rows(); ++i)
        for (Eigen::Index j = 0; j < x.cols(); ++j) x(i, j) = n01(rng);

    Eigen::MatrixXd w = x;
    f.solve_lower_in_place(w);
    CHECK((l * w - x).cwiseAbs().maxCoeff() < 1e-9);
    Eigen::VectorXd v = x.col(1);
    f.solve_lower_in_place(v);
    CHECK((v - w.col(1)).cwiseAbs().maxCoeff() < 1e-12);
    CHECK((f.lower_times(x) - l * x).cwiseAbs().maxCoeff() < 1e-9);
    CHECK((f.upper_times(x) - l.transpose() * x).cwiseAbs().maxCoeff() < 1e-9);
}

TEST_CASE("a covariance with a term between two cases beyond the shared directions takes the dense factor", "[reconcile]") {
    CfShaped s = cf_shaped(4, 5, 2, 5);
    s.c(0, 7) += 0.3;  // case 0 with case 1, not in u
    s.c(7, 0) += 0.3;
    const cf_ev::CovarianceFactor f(s.c, s.block_of, &s.u);
    CHECK_FALSE(f.structured());
    Eigen::MatrixXd x = Eigen::MatrixXd::Identity(s.c.rows(), s.c.rows());
    const Eigen::MatrixXd lx = f.lower_times(x);
    CHECK((lx * lx.transpose() - s.c).cwiseAbs().maxCoeff() < 1e-9);
    // Without the shared directions the between-case terms are not zero: dense as well.
    CHECK_FALSE(cf_ev::CovarianceFactor(cf_shaped(4, 5, 2, 5).c, s.block_of, nullptr).structured());
    // Block-diagonal alone is structured with no shared direction.
    const CfShaped b = cf_shaped(4, 5, 0, 6);
    const cf_ev::CovarianceFactor fb(b.c, b.block_of, nullptr);
    CHECK(fb.structured());
    const Eigen::MatrixXd lb = fb.lower_times(Eigen::MatrixXd::Identity(b.c.rows(), b.c.rows()));
    CHECK((lb * lb.transpose() - b.c).cwiseAbs().maxCoeff() < 1e-9);
}

TEST_CASE("a covariance that is not positive definite is refused, structured or dense", "[reconcile]") {
    CfShaped s = cf_shaped(3, 4, 1, 8);
    s.c(5, 5) = -1.0;
    CHECK_THROWS_AS(cf_ev::CovarianceFactor(s.c, s.block_of, &s.u), std::runtime_error);
    CHECK_THROWS_AS(cf_ev::CovarianceFactor(s.c, std::vector<int>(s.block_of.size(), 0), nullptr), std::runtime_error);
}
