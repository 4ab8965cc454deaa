// On the Botsch–Sorkine cactus, with γ = 0 (Q eliminated) and γ > 0 (Q
// kept in u): each rank's rows of the deformer's own H_u
// and D_u, assembled on part of the elements (Deformer::precompute_part),
// are those of the whole assembly; built by MUMPS over the ranks they match
// the single-process build (N, UD, H_r, BᵀD) to 1e-8 relative on each
// rank's rows, and Deformer::precompute_part goes on
// to the same float basis rows, which tile the mesh's rows over the ranks.
// Skipped with a message when ../shared is absent.
#include <catch2/catch.hpp>

#include "../shared_data.h"
#include "relative_difference.h"

#include "qpreduce/deform/deformer/deformer.h"
#include "qpreduce/deform/io/mesh_io.h"
#include "qpreduce/deform/io/scenario.h"
#include "qpreduce/distributed/mumps_subspace.h"

#include <mpi.h>

#include <filesystem>
#include <vector>
#include <string>

namespace {

using namespace qpreduce;
using MatD = Matrix<double>;

using testing_distributed::relative_difference;

}  // namespace

TEST_CASE("MUMPS subspace of the cactus matches CHOLMOD's", "[distributed][data]") {
  REQUIRE_SHARED_DATA(data);
  const std::string dir = data + "/meshes/botsch-sorkine";
  const deform::TriangleMesh mesh = deform::read_off(dir + "/cactus.off");
  deform::Scenario scenario = deform::scenario_from_sel_def(mesh.V, deform::read_sel(dir + "/cactus.sel"),
                                                            deform::read_def(dir + "/cactus.def"));
  scenario.model.F = mesh.F;
  // γ > 0 keeps Q in u: the rows of Q need each element's neighbours.
  const double gamma = GENERATE(0.0, 0.5);
  CAPTURE(gamma);
  deform::DeformerOptions o;
  o.energy.gamma = gamma;
  int rank = 0;
  MPI_Comm_rank(MPI_COMM_WORLD, &rank);

  int ranks = 1;
  MPI_Comm_size(MPI_COMM_WORLD, &ranks);

  // The whole system, from a one-process part on this rank alone (the
  // single-process assembly): the reference build and the rows to compare
  // the distributed assembly with (two or three chunks of elements a rank
  // at -np 2).
  SparseMatrix<double> H_whole, C_whole, D_whole;
  SubspaceOptions options_whole;
  const deform::Deformer::PartBuilder record = [&](const SparseMatrix<double>& H, const SparseMatrix<double>& C,
                                                   const SparseMatrix<double>& D, const SubspaceOptions& options,
                                                   deform::Deformer::SubspacePart* part) {
    H_whole = H;
    C_whole = C;
    D_whole = D;
    options_whole = options;
    SubspaceSolver<double> solver;
    const SubspaceSummary s = solver.precompute(H, C, D, options);
    part->N_rows = solver.subspace().N;
    part->UD_rows = solver.subspace().UD;
    part->Hr = solver.reduced_hessian();
    part->BtD = solver.reduced_linear_map();
    return s;
  };
  deform::Deformer alone;
  REQUIRE(alone.precompute_part(scenario.model, o, {}, {0, 1}, record, [](MatD*) {}).ok());
  SubspaceSolver<double> reference;
  REQUIRE(reference.precompute(H_whole, C_whole, D_whole, options_whole).ok());

  // Each rank assembles its rows only (on part of the elements), builds with
  // MUMPS and keeps its rows (Deformer::precompute_part).
  bool compared = false;
  const deform::Deformer::PartBuilder both = [&](const SparseMatrix<double>& H, const SparseMatrix<double>& C,
                                                 const SparseMatrix<double>& D, const SubspaceOptions& options,
                                                 deform::Deformer::SubspacePart* part) {
    const auto rows = distributed::owned_rows(H.cols(), MPI_COMM_WORLD);
    REQUIRE(H.rows() == rows.size());
    // The distributed assembly: this rank's rows of the whole H_u and D_u.
    const SparseMatrix<double> H_mine = H_whole.middleRows(rows.begin, rows.size());
    const SparseMatrix<double> D_mine = D_whole.middleRows(rows.begin, rows.size());
    CHECK(SparseMatrix<double>(H - H_mine).norm() < 1e-13 * H_mine.norm());
    CHECK(SparseMatrix<double>(D - D_mine).norm() < 1e-13 * D_mine.norm());
    CHECK(SparseMatrix<double>(C - C_whole).norm() == 0.0);
    distributed::DistributedSubspace mine;
    const auto dist = distributed::build_subspace_mumps_rows(MPI_COMM_WORLD, H, C, D, options, {}, &mine);
    INFO(dist.brief_report());
    REQUIRE(dist.ok());
    CHECK(relative_difference(mine.Hr, reference.reduced_hessian()) < 1e-8);
    CHECK(relative_difference(mine.BtD, reference.reduced_linear_map()) < 1e-8);
    CHECK(relative_difference(mine.N_rows, reference.subspace().N.middleRows(rows.begin, rows.size())) < 1e-8);
    CHECK(relative_difference(mine.UD_rows, reference.subspace().UD.middleRows(rows.begin, rows.size())) < 1e-8);
    compared = true;
    part->first_row = rows.begin;
    part->N_rows = std::move(mine.N_rows);
    part->UD_rows = std::move(mine.UD_rows);
    part->Hr = std::move(mine.Hr);
    part->BtD = std::move(mine.BtD);
    return SubspaceSummary(dist);
  };
  const deform::Deformer::SumOverProcesses sum = [](MatD* M) {
    MPI_Allreduce(MPI_IN_PLACE, M->data(), static_cast<int>(M->size()), MPI_DOUBLE, MPI_SUM, MPI_COMM_WORLD);
  };
  deform::Deformer part;
  const auto pre = part.precompute_part(scenario.model, o, {}, {rank, ranks}, both, sum);
  // With Q kept (4 rows an element after the 3 of each vertex) rank 0 holds
  // every vertex row at -np 2 and rank 1 the rows of Q of 7/8 of the
  // elements: each assembles nearly all of them, chunk by chunk
  // (tests/deform/deformer/cache_test.cpp checks fewer at 3 and 4 parts).
  if (ranks > 1 && gamma == 0.0) CHECK(pre.assembled_elements < pre.elements);
  REQUIRE(pre.ok());
  CHECK(compared);

  // The rest of precompute agrees too: this rank's rows of the float basis,
  // and the reduced operators every rank holds.
  deform::Deformer single;
  REQUIRE(single.precompute(scenario.model, o).ok());
  const auto rows = part.basis_rows();
  deform::Deformer::BasisRows a;
  part.basis_block(rows.first, rows.count, &a);  // K > 1: made from the rank's double rows of B
  const auto& b = single.reconstruction_basis();
  if (ranks == 1) {
    CHECK((rows.first == 0 && rows.count == b.rows()));  // one part is the whole: usable as it is
    CHECK(part.set_handles(scenario.handles).ok());
  } else {
    CHECK_THROWS_WITH(part.set_handles(scenario.handles), Catch::Contains("part of a distributed precompute"));
  }
  REQUIRE(a.rows() == rows.count);
  REQUIRE(a.cols() == b.cols());
  if (rows.count > 0) {  // a rank with rows of Q only has no vertex row
    CHECK((a - b.middleRows(rows.first, rows.count)).norm() / b.middleRows(rows.first, rows.count).norm() <
          1e-6);  // float basis: rounding of two doubles that agree to 1e-8
  }
  // The parts tile the 3n rows in rank order.
  long long mine[2] = {static_cast<long long>(rows.first), static_cast<long long>(rows.count)};
  std::vector<long long> all(2 * static_cast<size_t>(ranks));
  MPI_Allgather(mine, 2, MPI_LONG_LONG, all.data(), 2, MPI_LONG_LONG, MPI_COMM_WORLD);
  long long covered = 0;
  for (int r = 0; r < ranks; ++r) {
    if (all[2 * r + 1] == 0) continue;
    CHECK(all[2 * r] == covered);
    covered += all[2 * r + 1];
  }
  CHECK(covered == b.rows());
}
