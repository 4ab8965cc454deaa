// qpreduce — the strongest simple competitor of the reduced solver:
// a Cholesky factor of H cached once, and per demand a Schur complement.
//
// Eq. 1:  min_X ½XᵀHX − qᵀX  s.t.  AᵀX = b   (H n×n PSD, A n×m, b m, q n).
// The factor is of K = H + W·Wᵀ (n×n), with W (n×r) chosen so that K is
// positive definite: r = 0 when H is PD; for a PSD H, any sparse columns with
// ker H ∩ ker Wᵀ = {0}, e.g. √ρ·e_i (one pinned vertex) for a connected graph
// Laplacian, or √ρ·C. W is sparse so that W·Wᵀ adds little fill (a dense
// kernel vector would make K dense). With s = WᵀX, HX = KX − Ws,
// so the KKT system of Eq. 1 becomes
//     K X − W s + A Λ = q,   WᵀX − s = 0,   AᵀX = b,
// and with G_W = K⁻¹W (n×r, at precompute), G_A = K⁻¹A (n×m, per demand:
// m solves) and x₀ = K⁻¹q (one solve), X = x₀ + G_W s − G_A Λ where
//     [ WᵀG_W − I   −WᵀG_A ] [s]   [  −Wᵀx₀   ]
//     [ AᵀG_W       −AᵀG_A ] [Λ] = [ b − Aᵀx₀ ]          ((r+m) × (r+m))
// Exact (no regularisation error). Per demand: m + 1 solves with the cached
// factor, nnz(A)·m for the Schur complement, (r+m)³ for the small system.
#pragma once

#include "qpreduce/common.h"
#include "qpreduce/factorization.h"

#include <memory>
#include <string>

namespace qpreduce {

struct SchurBaselineOptions {
  Backend backend = Backend::Cholmod;  // an SPD backend (Cholmod or SimplicialLDLT)
  Index block_size = 64;               // right-hand sides per solve block
  // The small system counts as singular (Status::SingularKKT) when its
  // column-pivoted QR has rank < r + m at this relative threshold.
  double rank_tolerance = 1e-12;
  bool is_valid(std::string* why) const;
};

struct SchurBaselineSummary : Outcome {
  Index factor_nonzeros = 0;
  double seconds = 0.0;

 protected:
  void add_details(Report* out) const override;
};

class CachedCholeskySchur {
 public:
  // Factors K = H + W·Wᵀ and forms G_W = K⁻¹W. W: n×r sparse (may have 0 columns).
  // Throws std::invalid_argument on wrong sizes, NaN, invalid options; a K
  // that is not PD comes back as Status::SingularKKT.
  SchurBaselineSummary precompute(const SparseMatrix<double>& H, const SparseMatrix<double>& W,
                                  const SchurBaselineOptions& options = {});
  // Solves one demand. X is resized to n on success, left empty otherwise.
  // Throws std::invalid_argument on wrong sizes or before precompute.
  SchurBaselineSummary solve(const SparseMatrix<double>& A, const Vector<double>& b, const Vector<double>& q,
                             Vector<double>* X) const;

  bool ready() const { return factor_ != nullptr; }
  Index n() const { return n_; }

 private:
  SchurBaselineOptions options_;
  std::unique_ptr<SparseFactorization> factor_;
  SparseMatrix<double> W_;     // n×r
  Matrix<double> GW_, WtGW_;   // n×r K⁻¹W, r×r (WᵀG_W − I)
  Index n_ = 0;
};

}  // namespace qpreduce
