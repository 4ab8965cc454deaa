// MumpsBuild's steps (mumps_build.h): agreed input checks, the rank of C,
// the route and its distributed matrix rows, MUMPS analysis + factorization,
// a known-answer probe, the p solves by blocks, the reduced d × d algebra,
// N and UD row by row, and H_r, BᵀD, the residual.
#include "mumps_build.h"

namespace qpreduce::distributed::detail {

bool MumpsBuild::fail(Status status, std::string message) {
  summary.status = status;
  summary.message = std::move(message);
  summary.total_seconds = total.seconds();
  G.resize(0, 0);
  F.resize(0, 0);
  *out = DistributedSubspace{};
  return false;
}

bool MumpsBuild::fail_mumps(const MumpsSolver& solver, const std::string& what) {
  summary.mumps_infog1 = solver.infog1();
  summary.mumps_infog2 = solver.infog2();
  return fail(solver.infog1() == -10 || solver.infog1() == -6 ? Status::SingularKKT : Status::NumericalFailure,
              what + " failed (" + solver.message() + ")");
}

// CᵀC (d × d) as a sum over owned rows; full column rank required.
bool MumpsBuild::check_rank_of_C() {
  MatD CtC = MatD(C_rows.transpose() * C_rows);
  allreduce_sum(comm, CtC);
  const Index rank_c = qpreduce::numerical_rank(qpreduce::symmetric_eigenvalues(CtC),
                                                        options.rank_tolerance);
  if (rank_c < d) {
    return fail(Status::RankDeficientC,
                fmt::format("C has rank {} < d = {} columns: its columns are linearly dependent", rank_c, d));
  }
  return true;
}

std::vector<Index> MumpsBuild::augmented_columns() const {
  std::vector<Index> aug = options.augment_columns;
  if (!options.augment) {
    aug.clear();
  } else if (aug.empty()) {
    aug.resize(static_cast<size_t>(d));
    for (Index j = 0; j < d; ++j) aug[static_cast<size_t>(j)] = j;
  }
  return aug;
}

// Factors the K_order × K_order matrix of which this rank holds rows
// [K_begin, K_begin + K_rows.rows()), then solves K·x = K·v for a fixed v:
// a relative error above max_probe_error means K is singular to working
// precision. The rows of K·v are gathered to the host in rank order.
bool MumpsBuild::factor_and_probe(MumpsSolver& solver, const SpD& K_rows, Index K_begin, Index K_order,
                                  const char* what) {
  const Timer t;
  const bool factored = solver.factor(K_rows, K_begin, K_order);
  summary.factorize_seconds += t.seconds();
  summary.mumps_infog1 = solver.infog1();
  summary.mumps_infog2 = solver.infog2();
  if (!factored) return fail_mumps(solver, fmt::format("the MUMPS factorization of {}", what));
  summary.ordering = solver.ordering();
  summary.factor_nonzeros = solver.factor_nonzeros();
  summary.factor_megabytes_max = solver.megabytes_max();
  summary.factor_megabytes_total = solver.megabytes_total();

  Vector<double> v(K_order);
  for (Index i = 0; i < K_order; ++i) v(i) = 1.0 + 0.5 * std::sin(0.7 * static_cast<double>(i));
  // K·v by rows: the owned rows from K_rows; symmetric, so rows are complete.
  const Vector<double> Kv_rows = K_rows * v;
  std::vector<int> count(static_cast<size_t>(ranks)), offset(static_cast<size_t>(ranks));
  const int mine = static_cast<int>(K_rows.rows());
  MPI_Allgather(&mine, 1, MPI_INT, count.data(), 1, MPI_INT, comm);
  for (int r = 1; r < ranks; ++r) offset[size_t(r)] = offset[size_t(r - 1)] + count[size_t(r - 1)];
  MatD x(rank == 0 ? K_order : 0, 1);
  MPI_Gatherv(Kv_rows.data(), mine, MPI_DOUBLE, x.data(), count.data(), offset.data(), MPI_DOUBLE, 0, comm);
  if (!solver.solve_on_root(x)) return fail_mumps(solver, fmt::format("the MUMPS solve with {}", what));
  double err = 0.0;
  if (rank == 0) {
    err = (x.col(0) - v).norm() / v.norm();
    if (!std::isfinite(err)) err = std::numeric_limits<double>::infinity();
  }
  MPI_Bcast(&err, 1, MPI_DOUBLE, 0, comm);
  summary.probe_error = err;
  if (err > options.max_probe_error) {
    return fail(Status::SingularKKT,
                fmt::format("{} is singular to working precision (a solve with a known answer came back with "
                            "relative error {:.2e}): H is not positive definite on ker(Cᵀ)",
                            what, err));
  }
  return true;
}

// Solves `columns` right-hand sides in blocks: rank 0 fills each K_order × b
// block (fill(first column, block)), MUMPS solves it, and the rows of the
// first n unknowns go to their owners' `owned` (rows.size() × columns).
bool MumpsBuild::solve_columns(MumpsSolver& solver, Index K_order, Index columns,
                               const std::function<void(Index, MatD&)>& fill, MatD* owned) {
  return solve_blocks(solver, K_order, columns, fill, nullptr, owned);
}

// The same with D's columns on top of each block: gathered from the ranks'
// rows (one column of n doubles at a time) into rank 0's block.
bool MumpsBuild::solve_columns_of_D(MumpsSolver& solver, Index K_order, MatD* owned) {
  return solve_blocks(solver, K_order, k, {}, &D_rows, owned);
}

bool MumpsBuild::solve_blocks(MumpsSolver& solver, Index K_order, Index columns,
                              const std::function<void(Index, MatD&)>& fill, const SpD* top_rows, MatD* owned) {
  owned->resize(rows.size(), columns);
  const Index block = std::min<Index>(options.block_size, std::max<Index>(columns, 1));
  const Counts counts(parts);
  MatD rhs;
  Vector<double> mine;
  for (Index j = 0; j < columns; j += block) {
    const Index b = std::min(block, columns - j);
    if (rank == 0) {
      rhs.setZero(K_order, b);
      if (fill) fill(j, rhs);
    }
    for (Index c = 0; top_rows != nullptr && c < b; ++c) {
      mine = Vector<double>(top_rows->col(j + c));
      MPI_Gatherv(mine.data(), static_cast<int>(rows.size()), MPI_DOUBLE, rank == 0 ? rhs.col(c).data() : nullptr,
                  counts.count.data(), counts.offset.data(), MPI_DOUBLE, 0, comm);
    }
    if (!solver.solve_on_root(rhs)) return fail_mumps(solver, "a MUMPS block solve");
    // Column by column: the first n rows of each solution column, to their owners.
    for (Index c = 0; c < b; ++c) {
      MPI_Scatterv(rank == 0 ? rhs.col(c).data() : nullptr, counts.count.data(), counts.offset.data(), MPI_DOUBLE,
                   owned->col(j + c).data(), static_cast<int>(rows.size()), MPI_DOUBLE, 0, comm);
    }
  }
  return true;
}

// The PSD check by factorization: MUMPS LDLᵀ of H + τI must have no negative
// pivot (INFOG(12)) and not fail.
bool MumpsBuild::psd_by_factorization() {
  const Timer t;
  SpD shifted = H_rows;
  for (Index j = rows.begin; j < rows.end; ++j) shifted.coeffRef(j - rows.begin, j) += tau;
  MumpsSolver check(comm, Symmetry::Indefinite, mumps);
  const bool factored = check.factor(shifted, rows.begin, n);
  summary.check_psd_seconds += t.seconds();
  if (factored && check.negative_pivots() == 0) return true;
  return fail(Status::IndefiniteH,
              factored ? fmt::format("H is not positive semi-definite: H + {:.2e}·I has {} negative pivots (MUMPS "
                                     "LDLᵀ)", tau, check.negative_pivots())
                       : fmt::format("H is not positive semi-definite: H + {:.2e}·I failed to factor ({})", tau,
                                     check.message()));
}

namespace {

// The columns `which` of C (n × |which|), and the sum of their squared norms
// in *norm2.
SpD selected_columns(const SpD& C, const std::vector<Index>& which, double* norm2) {
  SpD out(C.rows(), static_cast<Index>(which.size()));
  std::vector<Eigen::Triplet<double>> t;
  *norm2 = 0.0;
  for (size_t c = 0; c < which.size(); ++c) {
    *norm2 += C.col(which[c]).squaredNorm();
    for (SpD::InnerIterator it(C, which[c]); it; ++it) t.emplace_back(it.row(), Index(c), it.value());
  }
  out.setFromTriplets(t.begin(), t.end());
  return out;
}

// The largest absolute row sum of A (0 when A has no rows).
double max_abs_row_sum(const SpD& A) {
  Vector<double> row_sums = Vector<double>::Zero(A.rows());
  for (Index j = 0; j < A.outerSize(); ++j)
    for (SpD::InnerIterator it(A, j); it; ++it) row_sums(it.row()) += std::abs(it.value());
  return row_sums.size() > 0 ? row_sums.maxCoeff() : 0.0;
}

}  // namespace

// Augmented route (or plain H when aug is empty): SPD factorization, G, F,
// S = CᵀG, the PSD certificate of subspace.h, then N and UD row by row.
bool MumpsBuild::augmented_route(const std::vector<Index>& aug) {
  double col_norm2 = 0.0;
  const SpD Cp = selected_columns(C, aug, &col_norm2);
  const double mean_diag = allreduce(comm, local_diagonal().cwiseAbs().sum(), MPI_SUM) / static_cast<double>(n);
  summary.rho = aug.empty() ? 0.0
                            : options.rho_scale * (mean_diag > 0 ? mean_diag : 1.0) /
                                  (col_norm2 / static_cast<double>(aug.size()));
  SpD augmented;  // the rows of H + ρCpCpᵀ, for the factorization only
  if (!aug.empty()) {
    const SpD Cp_rows = Cp.middleRows(rows.begin, rows.size());
    augmented = SpD(H_rows + summary.rho * SpD(Cp_rows * Cp.transpose())).pruned();
  }
  const SpD& Hrho_rows = aug.empty() ? H_rows : augmented;
  // Gershgorin bound on λ_max(H_ρ): the largest absolute row sum.
  const double hrho_bound = allreduce(comm, max_abs_row_sum(Hrho_rows), MPI_MAX);

  const char* what = aug.empty() ? "H" : "H + ρCCᵀ";
  MumpsSolver solver(comm, Symmetry::PositiveDefinite, mumps);
  if (!factor_and_probe(solver, Hrho_rows, rows.begin, n, what)) return false;
  SpD().swap(augmented);  // the factor has it; the rows of H stay, for H·B
  if (solver.negative_pivots() > 0) {
    if (options.check_psd && !psd_by_factorization()) return false;
    return fail(Status::SingularKKT,
                fmt::format("{} has {} negative pivots, so the KKT matrix [[H, C], [Cᵀ, 0]] is singular: H is not "
                            "positive definite on ker(Cᵀ)", what, solver.negative_pivots()));
  }

  const Timer t;
  const auto dense_cols = [](const SpD& S) {
    return [&S](Index j, MatD& block) { block.topRows(S.rows()) = MatD(S.middleCols(j, block.cols())); };
  };
  if (!solve_columns(solver, n, d, dense_cols(C), &G)) return false;
  if (!solve_columns_of_D(solver, n, &F)) return false;
  summary.solve_seconds = t.seconds();

  MatD S = MatD(C_rows.transpose() * G);
  allreduce_sum(comm, S);
  S = 0.5 * (S + S.transpose()).eval();
  const auto eig = qpreduce::symmetric_eigenvalues(S);
  summary.s_condition = eig.maxCoeff() / std::max(eig.minCoeff(), 1e-300);
  if (qpreduce::numerical_rank(eig, options.rank_tolerance) < d) {
    if (options.check_psd && !psd_by_factorization()) return false;
    return fail(Status::SingularKKT, fmt::format("S = Cᵀ({})⁻¹C is singular (condition {:.2e}): the KKT matrix "
                                                 "is singular to working precision", what, summary.s_condition));
  }
  // PSD certificate (subspace.h): λ_max(ρ·S_aug) ≤ 1 + τ/λ̄ certifies H + τI ⪰ 0.
  if (options.check_psd && !options.psd_check_by_factorization && !aug.empty()) {
    MatD T(aug.size(), aug.size());
    for (size_t a = 0; a < aug.size(); ++a)
      for (size_t b = 0; b < aug.size(); ++b) T(Index(a), Index(b)) = summary.rho * S(aug[a], aug[b]);
    const double lambda_max = qpreduce::symmetric_eigenvalues(T).maxCoeff();
    if (!(lambda_max - 1.0 <= tau / std::max(hrho_bound, 1e-300)) && !psd_by_factorization()) return false;
  } else if (options.check_psd && options.psd_check_by_factorization && !psd_by_factorization()) {
    return false;
  }

  // N = G·S⁻¹, UD = F − N·CᵀF, over owned rows.
  MatD Sinv = Eigen::LLT<MatD>(S).solve(MatD::Identity(d, d));
  Sinv = 0.5 * (Sinv + Sinv.transpose()).eval();
  MatD CtF = MatD(C_rows.transpose() * F);
  allreduce_sum(comm, CtF);
  MatD tmp;
  for (Index r = 0; r < G.rows(); r += kRowBlock) {  // in place, one row block of scratch
    const Index len = std::min(kRowBlock, G.rows() - r);
    tmp.noalias() = G.middleRows(r, len) * Sinv;
    G.middleRows(r, len) = tmp;
    if (k > 0) F.middleRows(r, len).noalias() -= tmp * CtF;
  }
  return true;
}

// KKT route: K = [[H, C], [Cᵀ, 0]] (SYM = 2), the last rank also holding the d
// rows of Cᵀ; [N UD] = top n rows of K⁻¹·[[0, D], [I, 0]].
bool MumpsBuild::kkt_route() {
  const bool last = rank == ranks - 1;
  const Index K_order = n + d;
  const Index K_rows_count = rows.size() + (last ? d : 0);
  SpD K_rows(K_rows_count, K_order);
  {
    std::vector<Eigen::Triplet<double>> t;
    for (Index j = 0; j < H_rows.outerSize(); ++j)
      for (SpD::InnerIterator it(H_rows, j); it; ++it) t.emplace_back(it.row(), j, it.value());
    for (Index j = 0; j < d; ++j)
      for (SpD::InnerIterator it(C_rows, j); it; ++it) t.emplace_back(it.row(), n + j, it.value());
    if (last) {
      for (Index j = 0; j < d; ++j)
        for (SpD::InnerIterator it(C, j); it; ++it) t.emplace_back(rows.size() + j, it.row(), it.value());
    }
    K_rows.setFromTriplets(t.begin(), t.end());
  }
  MumpsSolver solver(comm, Symmetry::Indefinite, mumps);
  if (!factor_and_probe(solver, K_rows, rows.begin, K_order, "the KKT matrix [[H, C], [Cᵀ, 0]]")) return false;
  SpD().swap(K_rows);  // the factor has it
  const Timer t;
  // Right-hand sides for N: e_j in row n + j; for UD: D on top.
  const auto n_rhs = [this](Index j, MatD& block) {
    for (Index c = 0; c < block.cols(); ++c) block(n + j + c, c) = 1.0;
  };
  if (!solve_columns(solver, K_order, d, n_rhs, &G)) return false;
  if (!solve_columns_of_D(solver, K_order, &F)) return false;  // D on top
  summary.solve_seconds = t.seconds();
  if (!all_true(comm, G.allFinite() && F.allFinite())) {
    return fail(Status::SingularKKT, "the KKT matrix is singular: MUMPS produced non-finite values");
  }
  if (options.check_psd && !psd_by_factorization()) return false;
  return true;
}

bool MumpsBuild::check_ud_rank(const MatD& DtUD) {
  if (!(k > 0 && options.check_dependent_cd)) return true;
  const MatD sym = 0.5 * (DtUD + DtUD.transpose());
  const auto eig = qpreduce::symmetric_eigenvalues(sym);
  const double hn = std::sqrt(allreduce(comm, H_rows.squaredNorm(), MPI_SUM));
  const double scale = std::max(eig.cwiseAbs().maxCoeff(), hn > 0 ? D_norm * D_norm / hn : 0.0);
  summary.ud_condition = eig.maxCoeff() / std::max(eig.minCoeff(), 1e-300);
  const Index rank_ud = (eig.array() > options.rank_tolerance * scale).count();
  if (rank_ud < k) {
    return fail(Status::DependentCD,
                fmt::format("C and D are linearly dependent: U·D has rank {} < k = {} (some combination of D's "
                            "columns lies in Span(C))", rank_ud, k));
  }
  return true;
}

// H_r = BᵀHB, BᵀD and the relative KKT residual of subspace.h, by column
// blocks of B = [N UD]: each block (n × b) is gathered to every rank, which
// multiplies its H rows by it; the partial sums over owned rows are reduced.
void MumpsBuild::reduced_operators() {
  const Timer t;
  const Index p = d + k;
  MatD Hr = MatD::Zero(p, p);
  MatD CtC = MatD(C_rows.transpose() * C_rows);
  allreduce_sum(comm, CtC);
  const Eigen::LDLT<MatD> CtC_ldlt(CtC);
  double r1sq = 0.0, r2sq = 0.0;
  const Index block = std::min(options.block_size, mumps.gather_columns);
  const Counts counts(parts);
  const auto column = [&](Index j) { return j < d ? G.col(j) : F.col(j - d); };
  MatD gathered, mine;
  for (Index j = 0; j < p; j += block) {
    const Index b = std::min(block, p - j);
    // Columns [j, j + b) of B, whole, on every rank; this rank's rows beside.
    gathered.resize(n, b);
    mine.resize(rows.size(), b);
    for (Index c = 0; c < b; ++c) {
      mine.col(c) = column(j + c);
      MPI_Allgatherv(mine.col(c).data(), static_cast<int>(rows.size()), MPI_DOUBLE, gathered.col(c).data(),
                     counts.count.data(), counts.offset.data(), MPI_DOUBLE, comm);
    }
    MatD HB = H_rows * gathered;  // owned rows of H·B_j
    Hr.middleCols(j, b).topRows(d).noalias() = G.transpose() * HB;
    if (k > 0) Hr.middleCols(j, b).bottomRows(k).noalias() = F.transpose() * HB;
    if (options.compute_residual) {
      for (Index c = 0; c < b; ++c) {
        if (j + c >= d) HB.col(c) -= D_rows.col(j + c - d);
      }
      MatD CtR = MatD(C_rows.transpose() * HB);
      allreduce_sum(comm, CtR);
      HB.noalias() -= C_rows * CtC_ldlt.solve(CtR);
      r1sq += HB.squaredNorm();
      MatD R2 = MatD(C_rows.transpose() * mine);
      allreduce_sum(comm, R2);
      for (Index c = 0; c < b; ++c) {
        if (j + c < d) R2(j + c, c) -= 1.0;
      }
      if (rank == 0) r2sq += R2.squaredNorm();
    }
  }
  allreduce_sum(comm, Hr);
  Hr = 0.5 * (Hr + Hr.transpose()).eval();
  out->Hr = std::move(Hr);
  out->BtD.resize(p, k);
  if (k > 0) {
    out->BtD.topRows(d) = MatD(D_rows.transpose() * G).transpose();
    out->BtD.bottomRows(k) = MatD(D_rows.transpose() * F).transpose();
    allreduce_sum(comm, out->BtD);
  }
  if (options.compute_residual) {
    r1sq = allreduce(comm, r1sq, MPI_SUM);
    r2sq = allreduce(comm, r2sq, MPI_SUM);
    const double bnorm = std::sqrt(allreduce(comm, G.squaredNorm() + F.squaredNorm(), MPI_SUM));
    const double hnorm = std::sqrt(allreduce(comm, H_rows.squaredNorm(), MPI_SUM));
    const double scale1 = hnorm * bnorm + (k > 0 ? D_norm : 0.0);
    const double scale2 = C.norm() * bnorm;
    const double r1 = scale1 > 0 ? std::sqrt(r1sq) / scale1 : std::sqrt(r1sq);
    const double r2 = scale2 > 0 ? std::sqrt(r2sq) / scale2 : std::sqrt(r2sq);
    summary.kkt_residual = std::max(r1, r2);
  }
  summary.reduce_seconds = t.seconds();
}

DistributedSummary MumpsBuild::run() {
  if (!check_rank_of_C()) return summary;
  const std::vector<Index> aug = augmented_columns();
  double fill = 0.0;
  for (Index j : aug) fill += std::pow(static_cast<double>(C.col(j).nonZeros()), 2);
  const double H_nnz = allreduce(comm, static_cast<double>(H_rows.nonZeros()), MPI_SUM);
  const bool use_kkt = options.backend == Backend::SparseLU ||
                       (options.backend == Backend::Auto && fill > options.max_augmentation_fill * H_nnz);
  summary.kkt_route = use_kkt;
  if (!(use_kkt ? kkt_route() : augmented_route(aug))) return summary;
  // The rows C fixes exactly, as the single-process build writes them (this
  // rank's rows of N and UD).
  qpreduce::snap_selected_rows(C, rows.begin, G, F);

  MatD DtUD = k > 0 ? MatD(D_rows.transpose() * F) : MatD(0, 0);
  allreduce_sum(comm, DtUD);
  if (!check_ud_rank(DtUD)) return summary;
  if (!all_true(comm, G.allFinite() && F.allFinite())) {
    fail(Status::NumericalFailure, "the subspace contains non-finite values");
    return summary;
  }
  out->n = n;
  out->d = d;
  out->k = k;
  out->rows = rows;
  reduced_operators();
  out->N_rows = std::move(G);
  out->UD_rows = std::move(F);
  summary.status = Status::Success;
  summary.message = fmt::format("subspace built on {} MPI rank(s) with MUMPS ({} ordering)", ranks, summary.ordering);
  summary.total_seconds = total.seconds();
  return summary;
}

}  // namespace qpreduce::distributed::detail
