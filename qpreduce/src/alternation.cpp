// Alternation (alternation.h): one setup per constraint set over the two
// private parts (alternation_parts.h) — Phase 1, its energy terms, the
// proximal block size and the fused form, in that order — and one solve.
#include "qpreduce/alternation.h"

#include "alternation_parts.h"

#include "qpreduce/anderson.h"
#include "qpreduce/checks.h"
#include "qpreduce/util/timer.h"

#include <fmt/format.h>

#include <cmath>
#include <stdexcept>

namespace qpreduce {

template <typename Scalar>
struct Alternation<Scalar>::Impl {
  FixedCoordinateSolver<Scalar> phase1;
  FusedAlternation<Scalar> fused;
  bool inputs = false;  // G_z, G_y were given (prepare or setup)
  // While `fused` holds a G_y with a follow_y term, the plain G_y the next
  // setup without one starts from (empty otherwise; G_z is fused's own,
  // which follow_y does not change).
  bool fused_followed = false;
  Matrix<Scalar> Gy_plain;
  Matrix<Scalar> follow_map;  // M_b·T (d × k), empty without T
  ConstraintSummary summary;
  bool energy = false;
  bool valid = false;  // the last setup ran to its end

  ConstraintSummary setup(const SubspaceSolver<Scalar>& solver, const Matrix<double>& Az, const Matrix<double>& Ay,
                          const Matrix<Scalar>* Gz, const Matrix<Scalar>* Gy,
                          const InputProjection<Scalar>& projection, const AlternationSetup& options);
};

namespace {

// M_b·T column by column, T's entries in ascending row order.
Matrix<double> follow_product(const Matrix<double>& Mb, const SparseMatrix<double>& T) {
  Matrix<double> out = Matrix<double>::Zero(Mb.rows(), T.cols());
  for (Index j = 0; j < T.outerSize(); ++j) {
    for (SparseMatrix<double>::InnerIterator it(T, j); it; ++it) out.col(j) += it.value() * Mb.col(it.row());
  }
  return out;
}

// G_z (q × d) and G_y (q × k) for `solver`, checked before anything changes.
void check_inputs(const char* who, const SubspaceSolver<double>& solver, const Matrix<double>& Gz,
                  const Matrix<double>& Gy) {
  check_size(fmt::format("{}: G_z columns (d)", who).c_str(), solver.d(), Gz.cols());
  check_size(fmt::format("{}: G_y columns (k)", who).c_str(), solver.k(), Gy.cols());
  check_size(fmt::format("{}: G_y rows (as G_z)", who).c_str(), Gz.rows(), Gy.rows());
  check_finite(fmt::format("{}: G_z", who).c_str(), Gz);
  check_finite(fmt::format("{}: G_y", who).c_str(), Gy);
}

}  // namespace

template <typename Scalar>
ConstraintSummary Alternation<Scalar>::Impl::setup(const SubspaceSolver<Scalar>& solver, const Matrix<double>& Az,
                                                   const Matrix<double>& Ay, const Matrix<Scalar>* Gz,
                                                   const Matrix<Scalar>* Gy,
                                                   const InputProjection<Scalar>& projection,
                                                   const AlternationSetup& options) {
  if (Gz == nullptr && !inputs) {
    throw std::invalid_argument("Alternation::setup: no G_z, G_y given yet (pass them, or call prepare first)");
  }
  const SparseMatrix<double>& T = options.follow_y;
  const bool follow = T.nonZeros() > 0;
  if (T.size() > 0) {
    check_size("Alternation::setup: follow_y rows (m)", Az.rows(), T.rows());
    check_size("Alternation::setup: follow_y columns (k)", Ay.cols(), T.cols());
    check_finite("Alternation::setup: follow_y", T);
  }
  // Checked before anything changes (Phase 1 checks its own inputs first).
  if (Gz != nullptr) check_inputs("Alternation::setup", solver, *Gz, *Gy);
  ConstraintSummary cs = phase1.set_reduced_constraints(solver, Az, Ay, options.constraints);
  // From here on a failure (out of memory) leaves no model rather than a
  // Phase 1 and a fused form of two different sets.
  valid = false;
  summary = cs;
  energy = false;
  follow_map.resize(0, 0);
  // The energy terms before the fused form, which reads them for
  // constraints on y.
  if (options.energy_terms && !follow && summary.ok() &&
      std::isfinite(projection.quadratic_term(Vector<Scalar>::Zero(Ay.cols())))) {
    phase1.form_energy_terms(solver);
    energy = true;
  }
  fused.set_proximal_block_size(projection.proximal_block_size());
  const int threads = options.constraints.threads;
  if (follow) {
    follow_map = follow_product(phase1.Mb(), T);
    if (Gy != nullptr) {
      Gy_plain = *Gy;
    } else if (!fused_followed) {
      Gy_plain = fused.Gy();
    }
    const Matrix<Scalar>& gz = Gz != nullptr ? *Gz : fused.Gz();
    const Matrix<Scalar> Gy_followed = Gy_plain + gz * follow_map;
    fused.set(phase1, gz, Gy_followed, threads, options.form, options.precision);
    fused_followed = true;
  } else if (Gz != nullptr) {
    fused.set(phase1, *Gz, *Gy, threads, options.form, options.precision);
    fused_followed = false;
  } else if (fused_followed) {
    fused.set(phase1, fused.Gz(), Gy_plain, threads, options.form, options.precision);
    fused_followed = false;
  } else {
    fused.set(phase1, threads, options.form, options.precision);  // the kept inputs, not compared again
  }
  if (!fused_followed) Gy_plain.resize(0, 0);
  inputs = true;
  valid = true;
  return summary;
}

template <typename Scalar>
Alternation<Scalar>::Alternation() : impl_(std::make_unique<Impl>()) {}

template <typename Scalar>
Alternation<Scalar>::~Alternation() = default;

template <typename Scalar>
Alternation<Scalar>::Alternation(const Alternation& other) : impl_(std::make_unique<Impl>(*other.impl_)) {}

template <typename Scalar>
Alternation<Scalar>& Alternation<Scalar>::operator=(const Alternation& other) {
  if (this != &other) *impl_ = *other.impl_;
  return *this;
}

// Moves swap, so that a moved-from object stays usable.
template <typename Scalar>
Alternation<Scalar>::Alternation(Alternation&& other) noexcept : impl_(std::make_unique<Impl>()) {
  impl_.swap(other.impl_);
}

template <typename Scalar>
Alternation<Scalar>& Alternation<Scalar>::operator=(Alternation&& other) noexcept {
  impl_.swap(other.impl_);
  return *this;
}

template <typename Scalar>
void Alternation<Scalar>::prepare(const SubspaceSolver<Scalar>& solver, const Matrix<Scalar>& Gz,
                                  const Matrix<Scalar>& Gy, const InputProjection<Scalar>& projection,
                                  FusedPrecision precision, bool shared_parts) {
  if (!solver.ready()) throw std::invalid_argument("Alternation::prepare: the subspace solver is not ready");
  check_inputs("Alternation::prepare", solver, Gz, Gy);
  Impl& I = *impl_;
  I.valid = false;
  if (shared_parts) I.phase1.prepare(solver);
  I.fused.set_proximal_block_size(projection.proximal_block_size());
  I.fused.prepare(I.phase1, Gz, Gy, precision);  // checks the rest; clears the fused form
  I.inputs = true;
  I.fused_followed = false;
  I.Gy_plain.resize(0, 0);
  I.follow_map.resize(0, 0);
  I.summary = ConstraintSummary{};
  I.energy = false;
  I.valid = false;
}

template <typename Scalar>
ConstraintSummary Alternation<Scalar>::setup(const SubspaceSolver<Scalar>& solver, const Matrix<double>& Az,
                                             const Matrix<double>& Ay, const Matrix<Scalar>& Gz,
                                             const Matrix<Scalar>& Gy, const InputProjection<Scalar>& projection,
                                             const AlternationSetup& options) {
  return impl_->setup(solver, Az, Ay, &Gz, &Gy, projection, options);
}

template <typename Scalar>
ConstraintSummary Alternation<Scalar>::setup(const SubspaceSolver<Scalar>& solver, const Matrix<double>& Az,
                                             const Matrix<double>& Ay, const InputProjection<Scalar>& projection,
                                             const AlternationSetup& options) {
  return impl_->setup(solver, Az, Ay, nullptr, nullptr, projection, options);
}

template <typename Scalar>
ConstraintSummary Alternation<Scalar>::setup(const SubspaceSolver<Scalar>& solver, const SparseMatrix<Scalar>& A,
                                             const Matrix<Scalar>& Gz, const Matrix<Scalar>& Gy,
                                             const InputProjection<Scalar>& projection,
                                             const AlternationSetup& options) {
  const Timer timer;
  Matrix<double> Az, Ay;
  detail::full_space_rows("Alternation::setup", solver, A, &Az, &Ay);
  ConstraintSummary summary = impl_->setup(solver, Az, Ay, &Gz, &Gy, projection, options);
  summary.seconds = timer.seconds();
  impl_->summary.seconds = summary.seconds;
  return summary;
}

template <typename Scalar>
AlternationResults Alternation<Scalar>::solve(InputProjection<Scalar>& projection,
                                              const Eigen::Ref<const Vector<Scalar>>& b,
                                              const AlternationSettings& settings, Eigen::Ref<Vector<Scalar>> z,
                                              Eigen::Ref<Vector<Scalar>> y) {
  Impl& I = *impl_;
  if (!ready()) throw std::invalid_argument("Alternation::solve: no constraint set (call setup first)");
  std::string why;
  if (!settings.is_valid(&why)) throw std::invalid_argument("Alternation::solve: " + why);
  if (settings.anderson_window > 0 && !I.energy) {
    throw std::invalid_argument(
        "Alternation::solve: accelerated rounds (anderson_window > 0) need the energy terms, which this setup did "
        "not form (energy_terms false, follow_y, constraints not solved exactly, or a projection without "
        "quadratic_term)");
  }
  AlternationResults results = I.fused.run(I.phase1, projection, b, settings, z, y);
  if (I.follow_map.size() > 0) z.noalias() += I.follow_map * y;  // the right-hand sides that follow y
  return results;
}

template <typename Scalar>
double Alternation<Scalar>::energy(InputProjection<Scalar>& projection, const Eigen::Ref<const Vector<Scalar>>& b,
                                   const Eigen::Ref<const Vector<Scalar>>& y, double* slack) {
  Impl& I = *impl_;
  if (!ready()) throw std::invalid_argument("Alternation::energy: no constraint set (call setup first)");
  check_size("Alternation::energy: b (m)", m(), b.size());
  check_size("Alternation::energy: y (k)", k(), y.size());
  if (slack) *slack = 0.0;
  if (!I.energy) return std::numeric_limits<double>::quiet_NaN();
  return I.fused.energy(I.phase1, projection, b, y, slack);
}

template <typename Scalar>
void Alternation<Scalar>::phase_one(const Eigen::Ref<const Vector<Scalar>>& b,
                                    const Eigen::Ref<const Vector<Scalar>>& y, Eigen::Ref<Vector<Scalar>> z) const {
  const Impl& I = *impl_;
  if (!ready()) throw std::invalid_argument("Alternation::phase_one: no constraint set (call setup first)");
  check_size("Alternation::phase_one: b (m)", m(), b.size());
  check_size("Alternation::phase_one: y (k)", k(), y.size());
  check_size("Alternation::phase_one: z (d)", d(), z.size());
  I.phase1.solve(b, y, z);
  if (I.follow_map.size() > 0) z.noalias() += I.follow_map * y;
}

template <typename Scalar>
bool Alternation<Scalar>::ready() const {
  return impl_->valid && impl_->phase1.ready() && impl_->fused.ready();
}
template <typename Scalar>
Index Alternation<Scalar>::d() const {
  return impl_->phase1.d();
}
template <typename Scalar>
Index Alternation<Scalar>::k() const {
  return impl_->phase1.k();
}
template <typename Scalar>
Index Alternation<Scalar>::m() const {
  return impl_->phase1.m();
}
template <typename Scalar>
const ConstraintSummary& Alternation<Scalar>::constraint_summary() const {
  return impl_->summary;
}
template <typename Scalar>
bool Alternation<Scalar>::energy_terms() const {
  return impl_->energy;
}
template <typename Scalar>
bool Alternation<Scalar>::constrained_y() const {
  return impl_->fused.constrained_y();
}
template <typename Scalar>
const Vector<double>& Alternation<Scalar>::proximal_weights() const {
  return impl_->fused.proximal_weights();
}
template <typename Scalar>
bool Alternation<Scalar>::factored() const {
  return impl_->fused.factored();
}
template <typename Scalar>
bool Alternation<Scalar>::float_set() const {
  return impl_->fused.float_set();
}
template <typename Scalar>
bool Alternation<Scalar>::second_order(const InputProjection<Scalar>& projection,
                                       const AlternationSettings& settings) const {
  return impl_->fused.second_order(projection, settings);
}
template <typename Scalar>
bool Alternation<Scalar>::reports_energy(const InputProjection<Scalar>& projection,
                                         const AlternationSettings& settings) const {
  return impl_->fused.path(projection, settings) != FusedAlternation<Scalar>::Path::Plain;
}
template <typename Scalar>
const Matrix<Scalar>& Alternation<Scalar>::Mb() const {
  return impl_->phase1.Mb();
}
template <typename Scalar>
Matrix<Scalar> Alternation<Scalar>::MY() const {
  Matrix<Scalar> MY = impl_->phase1.MY();
  if (impl_->follow_map.size() > 0) MY += impl_->follow_map;
  return MY;
}

template class Alternation<double>;

}  // namespace qpreduce
