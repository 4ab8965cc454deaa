// Laplace–Beltrami eigenpairs and the spectral embedding: sparse against
// dense, and failures reported as a status.
#include <catch2/catch.hpp>

#include "proxies_test_util.h"

#include <cmath>
#include <stdexcept>

using namespace qpreduce;
using namespace qpreduce::deform;
using namespace proxies_test;

TEST_CASE("Laplace–Beltrami eigenpairs: Spectra shift-invert agrees with the dense solver", "[spectral]") {
  const Backend backend = GENERATE(Backend::Cholmod, Backend::SimplicialLDLT);
  CAPTURE(to_string(backend));
  const Surface s = icosphere(3);  // 642 vertices: above dense_max_size
  const SparseMatrix<double> L = cotangent_laplacian(s.V, s.F);
  const Eigen::VectorXd m = lumped_mass(s.V, s.F);
  SpectralOptions o;
  o.backend = backend;
  Eigenpairs sparse, dense;
  const SpectralSummary ss = laplacian_eigenpairs(L, m, 10, -0.01, o, &sparse);
  INFO(ss.brief_report());
  REQUIRE(ss.ok());
  CHECK(ss.lanczos_operations > 0);
  CHECK(ss.max_relative_residual < 1e-10);
  o.dense_max_size = 1000;
  const SpectralSummary ds = laplacian_eigenpairs(L, m, 10, -0.01, o, &dense);
  REQUIRE(ds.ok());
  CHECK(ds.lanczos_operations == 0);
  CHECK((sparse.values - dense.values).cwiseAbs().maxCoeff() <= 1e-9 * dense.values.maxCoeff());
  // M-orthonormal.
  const Eigen::MatrixXd G = sparse.vectors.transpose() * m.asDiagonal() * sparse.vectors;
  CHECK((G - Eigen::MatrixXd::Identity(10, 10)).cwiseAbs().maxCoeff() <= 1e-9);
  // Unit sphere: λ_0 = 0, then l(l+1) with multiplicity 2l+1 (2, then 6), up to discretisation.
  CHECK(std::abs(sparse.values[0]) <= 1e-9);
  for (int j = 1; j <= 3; ++j) CHECK(sparse.values[j] == Approx(2.0).epsilon(0.02));
  for (int j = 4; j <= 8; ++j) CHECK(sparse.values[j] == Approx(6.0).epsilon(0.03));
}

TEST_CASE("laplacian_eigenpairs reports non-convergence as a status, not silently", "[spectral][errors]") {
  const Surface s = icosphere(3);
  const SparseMatrix<double> L = cotangent_laplacian(s.V, s.F);
  const Eigen::VectorXd m = lumped_mass(s.V, s.F);
  SpectralOptions o;
  o.max_restarts = 1;
  o.min_lanczos_vectors = 2;
  o.tolerance = 1e-300;
  Eigenpairs pairs;
  pairs.values = Eigen::VectorXd::Constant(1, 7.0);
  const SpectralSummary summary = laplacian_eigenpairs(L, m, 10, -0.01, o, &pairs);
  CHECK(summary.status == Status::NumericalFailure);
  CHECK_THAT(summary.message, Catch::Contains("did not converge"));
  CHECK(pairs.values.size() == 1);  // untouched
  CHECK_THROWS_AS(laplacian_eigenpairs(L, m, 10, 0.5, SpectralOptions{}, &pairs), std::invalid_argument);
  CHECK_THROWS_AS(laplacian_eigenpairs(L, m, 700, -0.01, SpectralOptions{}, &pairs), std::invalid_argument);

  // And through the clustering entry point.
  ClusterOptions co;
  co.spectral = o;
  Clustering clusters;
  const ClusterSummary cs = compute_rotation_clusters(s.V, s.F, ClusterElement::Vertex, 8, co, &clusters);
  CHECK(cs.status == Status::NumericalFailure);
  CHECK_FALSE(cs.message.empty());
  CHECK(clusters.labels.empty());
}
