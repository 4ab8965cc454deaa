// qpreduce — common types, status codes and argument checks.
//
// Three layers of errors:
//   * `assert` on hot-path contracts (sizes inside per-frame loops);
//   * `std::invalid_argument` at the API boundary, with "expected N, got M";
//   * numerical outcomes (not positive definite, rank deficient, infeasible)
//     as a `Status` plus a message in a summary struct, never a silent zero.
// The argument checks themselves are in checks.h.
#pragma once

#include <Eigen/Core>
#include <Eigen/SparseCore>

#include "qpreduce/report.h"

#include <string>

namespace qpreduce {

using Index = Eigen::Index;

template <typename Scalar>
using SparseMatrix = Eigen::SparseMatrix<Scalar, Eigen::ColMajor, int>;
template <typename Scalar>
using Matrix = Eigen::Matrix<Scalar, Eigen::Dynamic, Eigen::Dynamic>;
template <typename Scalar>
using Vector = Eigen::Matrix<Scalar, Eigen::Dynamic, 1>;

// Outcome of a numerical step. Every summary starts at NotRun.
enum class Status {
  NotRun,
  Success,
  // Hard constraints could not all hold (over-determined or inconsistent):
  // the answer satisfies them in the least-squares sense.
  ConstraintsLeastSquares,
  // C (the constraint design space) does not have full column rank.
  RankDeficientC,
  // Some combination of D's columns lies in Span(C) (U·D is rank deficient).
  DependentCD,
  // H is not positive semi-definite.
  IndefiniteH,
  // The KKT matrix [[H, C], [Cᵀ, 0]] (or a reduced one) is singular: H is not
  // positive definite on ker(Cᵀ).
  SingularKKT,
  // The (reduced) problem has no unique minimiser.
  Unbounded,
  // Anything else a factorization reported.
  NumericalFailure,
};

const char* to_string(Status status);

// True for Success and for answers that are usable but qualified
// (ConstraintsLeastSquares).
inline bool usable(Status status) {
  return status == Status::Success || status == Status::ConstraintsLeastSquares;
}

// What every summary starts with (SubspaceSummary, ConstraintSummary,
// PrecomputeSummary, ...): the status of the step, which starts at NotRun,
// and a message for a person. Every stateful solver reports a failed
// numerical step this way, never by throwing. Each summary adds its typed
// part (counts, residuals, timings) to report().
struct Outcome {
  Status status = Status::NotRun;
  std::string message;

  Outcome() = default;
  Outcome(const Outcome&) = default;
  Outcome(Outcome&&) = default;
  Outcome& operator=(const Outcome&) = default;
  Outcome& operator=(Outcome&&) = default;
  virtual ~Outcome() = default;

  // Status::Success alone.
  bool ok() const { return status == Status::Success; }
  // Success, or an answer that holds with a qualification the message states
  // (Status::ConstraintsLeastSquares).
  bool usable() const { return qpreduce::usable(status); }
  // One line: "<status>" or "<status>: <message>"; summaries with a natural
  // one-line reading (SubspaceSummary, ClusterSummary) say more.
  virtual std::string brief_report() const;
  // Every field: "status", "message", then the summary's own, in the order
  // they are declared, under their C++ names (nested summaries nested;
  // per-round histories left out). The JSON of the apps and Python's
  // to_dict() are this.
  Report report() const;
  // report() as text, one "key: value" line per field.
  std::string full_report() const;

 protected:
  // Appends the summary's own fields to *out (nothing for a bare Outcome).
  virtual void add_details(Report* out) const;
};

}  // namespace qpreduce
