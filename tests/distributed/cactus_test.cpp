// On the Botsch–Sorkine cactus: the deformer's own (H_u, C, D_u) built by
// MUMPS over the ranks matches the single-process build (N, UD, H_r, BᵀD)
// to 1e-8 relative, and precompute goes on to the same reduced operators.
// Skipped with a message when ../shared is absent.
#include <catch2/catch.hpp>

#include "qpreduce/deform/deformer/deformer.h"
#include "qpreduce/deform/io/mesh_io.h"
#include "qpreduce/deform/io/scenario.h"
#include "qpreduce/distributed/mumps_subspace.h"

#include <mpi.h>

#include <filesystem>
#include <string>

namespace {

using namespace qpreduce;
using MatD = Matrix<double>;

double relative_difference(const MatD& A, const MatD& B) {
  return (A - B).norm() / std::max(B.norm(), 1e-300);
}

}  // namespace

TEST_CASE("MUMPS subspace of the cactus matches CHOLMOD's", "[distributed][data]") {
  const std::string dir = std::string(QPREDUCE_SHARED_DIR) + "/data/meshes/botsch-sorkine";
  if (!std::filesystem::exists(dir + "/cactus.off")) {
    WARN("shared data not found (" << dir << "/cactus.off); skipped");
    return;
  }
  const deform::TriangleMesh mesh = deform::read_off(dir + "/cactus.off");
  deform::Scenario scenario =
      deform::scenario_from_sel_def(mesh.V, deform::read_sel(dir + "/cactus.sel"), deform::read_def(dir + "/cactus.def"));
  scenario.model.F = mesh.F;
  int rank = 0;
  MPI_Comm_rank(MPI_COMM_WORLD, &rank);

  // The builder runs both builds on the deformer's own system.
  bool compared = false;
  const deform::Deformer::SubspaceBuilder both = [&](const SparseMatrix<double>& H, const SparseMatrix<double>& C,
                                                     const SparseMatrix<double>& D, const SubspaceOptions& options,
                                                     VariationalSubspace<double>* B, MatD* Hr, MatD* BtD) {
    SubspaceSolver<double> reference;
    const SubspaceSummary ref = reference.precompute(H, C, D, options);
    REQUIRE(ref.ok());
    const auto dist = distributed::build_subspace_mumps_on_root(MPI_COMM_WORLD, H, C, D, options, {}, 0, B, Hr, BtD);
    INFO(dist.brief_report());
    REQUIRE(dist.ok());
    CHECK(relative_difference(*Hr, reference.reduced_hessian()) < 1e-8);
    CHECK(relative_difference(*BtD, reference.reduced_linear_map()) < 1e-8);
    if (rank == 0) {
      CHECK(relative_difference(B->N, reference.subspace().N) < 1e-8);
      CHECK(relative_difference(B->UD, reference.subspace().UD) < 1e-8);
      compared = true;
      return SubspaceSummary(dist);
    }
    SubspaceSummary not_here = dist;
    not_here.status = Status::NotRun;  // the subspace lives on rank 0
    return not_here;
  };
  deform::Deformer distributed_deformer;
  const auto pre = distributed_deformer.precompute(scenario.model, {}, {}, both);
  if (rank != 0) {
    CHECK(pre.status == Status::NotRun);
    return;
  }
  REQUIRE(pre.ok());
  CHECK(compared);

  // The rest of precompute (M_N, M_U, the float basis) agrees too.
  deform::Deformer single;
  REQUIRE(single.precompute(scenario.model).ok());
  const auto& a = distributed_deformer.reconstruction_basis();
  const auto& b = single.reconstruction_basis();
  REQUIRE(a.rows() == b.rows());
  REQUIRE(a.cols() == b.cols());
  CHECK((a - b).norm() / b.norm() < 1e-6);  // float basis: rounding of two doubles that agree to 1e-8
}
