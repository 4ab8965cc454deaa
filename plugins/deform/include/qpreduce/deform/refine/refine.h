// qpreduce::deform — full-space finish ("refine") of a reduced pose.
//
// The reduced deformer (deformer.h) answers in microseconds with V′ in the
// variational subspace; when the handles rest, a Refiner takes that pose as
// the initial guess of full-space local-global ARAP (reference.h) and runs
// rounds, optionally Anderson-accelerated, until the energy settles:
//     min_{V′, R}  E(V′, R) = ½ Σ_k Σ_{(i,j)∈G_k} c_ijk ‖e′_ij − r_k e_ij‖²
//     subject to the handle constraints of Deformer::set_handles,
// classic ARAP (paper Eq. 6: spokes-and-rims on surfaces, one element per
// tet) by default, E′ (Eq. 8–10) on request. V′ and the input pose are
// n × 3; the rotations are 9r (one 3 × 3 per element).
//
// The factorization of the global step depends only on the handle set: the
// Refiner re-factors when refine() is given a handle set different from the
// previous one and reuses it while only the targets move.
//
// Usage:
//   Refiner refiner;
//   refiner.precompute(model);                     // elements, energy matrices
//   RefineSummary s = refiner.refine(handles, targets, reduced_pose, &refined);
//   // s.rounds, s.seconds, s.arap_energy, s.rms_from_input, …
#pragma once

#include "qpreduce/deform/reference/reference.h"

#include <functional>
#include <limits>
#include <memory>
#include <string>
#include <vector>

namespace qpreduce::deform {

struct RefineOptions {
  // Stop once the pose is estimated to be within distance_tolerance of the
  // converged shape, RMS over the vertices and divided by the bounding-box
  // diagonal (RefineSummary::estimated_distance; ReferenceOptions::
  // distance_tolerance). The default 1e-4 (0.01 %) leaves the refined pose
  // within 0.1 % of the tightly converged one on the shared models
  // (docs/quality.md, "The refine's default stop"). Finite and ≥ 0.
  double distance_tolerance = 1e-4;
  // Also stop when the relative energy change of a round or the relative
  // fixed-point residual is ≤ tolerance (ReferenceOptions::tolerance): a
  // test that can fire in a flat valley far from the minimum; 0 (the
  // default) leaves it out. With both 0 the rounds run to the reference test
  // (step 1e-10 of the diagonal and energy change 1e-13). Finite and ≥ 0.
  double tolerance = 0.0;
  // Anderson window, in [0, 16]; 0 = plain local-global. 5 is the usual
  // choice of Peng et al. (2018): larger windows cost O(n·m) more per round
  // for little gain on ARAP.
  int anderson_window = 5;
  // After this many rounds, trust-region Newton steps on the classic energy
  // replace them (ReferenceOptions::newton_after; docs/deform.md, "The
  // Newton finish"): they cross the flat valleys where rounds crawl. 0:
  // rounds only. ≥ 0.
  int newton_after = 64;
  // Round limit; a refine that reaches it reports converged = false.
  int max_iterations = 20000;
  // The energy refined: classic ARAP, or E′ with these parameters (the
  // model then needs its rotational clusters).
  ReferenceEnergy energy = ReferenceEnergy::ClassicArap;
  EnergyParameters parameters;
  // The global step's factorization. Auto: CHOLMOD's simplicial LDLᵀ when
  // the step separates into one factor for the three axes (classic ARAP
  // with whole vertices and patches held; reference.h), CHOLMOD's
  // supernodal LLᵀ otherwise.
  Backend backend = Backend::Auto;
  // Threads for the rounds (ReferenceOptions::threads); 0: all
  // (omp_get_max_threads()). The refined pose does not depend on it.
  int threads = 0;

  // False with a reason, e.g. "tolerance must be finite and ≥ 0, got -1".
  bool is_valid(std::string* why) const;
};

struct RefineSummary : Outcome {
  int rounds = 0;
  bool converged = false;             // the tolerance test held (not the round limit)
  bool cancelled = false;             // the cancel hook stopped it; the pose is the last accepted one
  bool refactored = false;            // this call factored the global step (new handle set)
  bool axis_separable = false;        // one factor serves x, y and z (HandleSetSummary::axis_separable)
  int rejected_steps = 0;             // Anderson steps refused by the energy safeguard
  int newton_steps = 0;               // Newton steps among the rounds (RefineOptions::newton_after)
  int cg_iterations = 0;              // their Hessian products, one solve with the global step's factor each
  double seconds = 0.0;               // the rounds (the time to converge from the input pose)
  double setup_seconds = 0.0;         // the factorization of this call (0 when reused)
  double initial_energy = 0.0;        // the refined energy (classic or E′) of the input pose
  double energy = 0.0;                // the refined energy of the result
  double arap_energy = 0.0;           // classic ARAP energy of the result (arap_energy.h)
  double fixed_point_residual = 0.0;  // ‖G(z) − z‖ / ‖z‖ of the last round
  // How far the result is estimated to be from the converged shape, RMS
  // over the vertices / the bounding-box diagonal (ReferenceSummary::
  // estimated_distance; infinite when fewer than two rounds ran).
  double estimated_distance = std::numeric_limits<double>::infinity();
  double handle_residual = 0.0;       // largest constraint violation (absolute)
  // Distances between the input pose and the result, over the bounding-box
  // diagonal of the rest pose: root-mean-square and largest per-vertex.
  double rms_from_input = 0.0, max_from_input = 0.0;
  // After each round: the refined energy and the seconds since the rounds
  // began.
  std::vector<double> round_energy, round_seconds;

 protected:
  void add_details(Report* out) const override;
};

class Refiner {
 public:
  Refiner();
  ~Refiner();
  Refiner(Refiner&&) noexcept;
  Refiner& operator=(Refiner&&) noexcept;

  // Builds the elements and energy matrices for the rest pose of `model`.
  // Throws std::invalid_argument on invalid options or a bad model
  // (as LocalGlobalArap::precompute).
  void precompute(const DeformableMesh& model, const RefineOptions& options = {});

  // Replaces tolerance, anderson_window, newton_after, max_iterations and threads (the energy,
  // parameters and backend stay those of precompute). Throws
  // std::invalid_argument on invalid options or before precompute.
  void set_options(const RefineOptions& options);
  const RefineOptions& options() const;

  // Refines `pose` (n × 3, e.g. the reduced deformer's; empty: the rest
  // pose) under `handles` at `targets` and writes the result (n × 3) to
  // *out. Re-factors only when `handles` differs from the last call's.
  //   cancel  optional; checked once per round (LocalGlobalArap::solve)
  // Throws std::invalid_argument before precompute, on a pose with the wrong
  // row count or non-finite entries, on bad handles or targets
  // (LocalGlobalArap). A failed factorization or non-finite round comes
  // back as the summary's status and message (*out is then the last valid
  // pose, or the input pose when nothing ran).
  RefineSummary refine(const Handles& handles, const HandleTargets& targets, const Vertices& pose, Vertices* out,
                       const std::function<bool()>& cancel = {});

  const RotationElements& elements() const;

 private:
  struct State;
  std::unique_ptr<State> state_;
};

}  // namespace qpreduce::deform
