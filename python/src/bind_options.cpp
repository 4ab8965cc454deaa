// Status, Backend, the options structs and the summaries (common.h,
// subspace.h, subspace_solver.h, full_solve.h, quotient.h, theorem.h).
#include "bindings.h"
#include "fields.h"

#include <qpreduce/alternation.h>
#include <qpreduce/full_solve.h>
#include <qpreduce/quotient.h>
#include <qpreduce/subspace_solver.h>
#include <qpreduce/theorem.h>

#include <pybind11/stl.h>

namespace qpreduce::python {

namespace {

void bind_enums(py::module_& m) {
  py::enum_<Status>(m, "Status", "Outcome of a numerical step (common.h). Every summary starts at NotRun.")
      .value("NotRun", Status::NotRun)
      .value("Success", Status::Success)
      .value("ConstraintsLeastSquares", Status::ConstraintsLeastSquares,
             "Hard constraints could not all hold: satisfied in the least-squares sense.")
      .value("RankDeficientC", Status::RankDeficientC, "C does not have full column rank.")
      .value("DependentCD", Status::DependentCD, "Some combination of D's columns lies in Span(C).")
      .value("IndefiniteH", Status::IndefiniteH, "H is not positive semi-definite.")
      .value("SingularKKT", Status::SingularKKT, "The KKT matrix is singular: H is not PD on ker(Cᵀ).")
      .value("Unbounded", Status::Unbounded, "The (reduced) problem has no unique minimiser.")
      .value("NumericalFailure", Status::NumericalFailure, "Anything else a factorization reported.");
  py::enum_<RoundStop>(m, "RoundStop", "What ended a frame's rounds (alternation.h).")
      .value("RoundLimit", RoundStop::RoundLimit, "The cap (iterations) was reached.")
      .value("Tolerance", RoundStop::Tolerance, "The fixed-point residual met the tolerance.")
      .value("TimeBudget", RoundStop::TimeBudget, "The time budget was spent first.");
  py::enum_<Backend>(m, "Backend", "Factorization backend (factorization.h).")
      .value("Auto", Backend::Auto)
      .value("Cholmod", Backend::Cholmod)
      .value("SimplicialLDLT", Backend::SimplicialLDLT)
      .value("SparseLU", Backend::SparseLU);
  py::enum_<TheoremStatus>(m, "TheoremStatus", "Whether Theorem 4.10 applies to a demand (theorem.h).")
      .value("NotRun", TheoremStatus::NotRun)
      .value("Applies", TheoremStatus::Applies, "ρ < 1 and Â has full column rank: the bound is finite.")
      .value("DoesNotApply", TheoremStatus::DoesNotApply, "ρ ≥ 1: no claim, bound = inf.")
      .value("RankDeficientA", TheoremStatus::RankDeficientA, "Â lacks full column rank.")
      .value("IndefiniteH", TheoremStatus::IndefiniteH, "H is not PSD.")
      .value("SolveFailed", TheoremStatus::SolveFailed, "The exact or the engine's solve failed.");
}

void bind_option_structs(py::module_& m) {
  py::class_<SubspaceOptions> subspace(m, "SubspaceOptions",
                                       "Options of precompute / build_subspace (subspace.h); keyword construction.");
  Fields(subspace, "SubspaceOptions")
      .rw("backend", &SubspaceOptions::backend, "Backend.Auto: CHOLMOD on H_ρ, or SparseLU on the KKT matrix.")
      .rw("rho_scale", &SubspaceOptions::rho_scale, "ρ = rho_scale·mean(diag H)/mean(‖c_j‖²). Default 1.")
      .rw("augment_columns", &SubspaceOptions::augment_columns, "Columns of C for the augmentation; [] = all.")
      .rw("augment", &SubspaceOptions::augment, "False: factor H itself (needs H PD). Default True.")
      .rw("max_augmentation_fill", &SubspaceOptions::max_augmentation_fill,
          "Auto backend: SparseLU when Σ nnz(c_j)² > this·nnz(H). Default 4.")
      .rw("ordering_groups", &SubspaceOptions::ordering_groups, "Group id per unknown for the ordering; [] = none.")
      .rw("block_size", &SubspaceOptions::block_size, "Right-hand sides per block solve. Default 64.")
      .rw("symmetry_tolerance", &SubspaceOptions::symmetry_tolerance, "‖H − Hᵀ‖_F ≤ this·‖H‖_F. Default 1e-10.")
      .rw("check_psd", &SubspaceOptions::check_psd, "Check that H is PSD. Default True.")
      .rw("psd_shift", &SubspaceOptions::psd_shift, "τ = psd_shift·max|H_ii| of the PSD check. Default 1e-8.")
      .rw("psd_check_by_factorization", &SubspaceOptions::psd_check_by_factorization,
          "Always factor H + τI instead of the certificate. Default False.")
      .rw("rank_tolerance", &SubspaceOptions::rank_tolerance, "λ_min < this·λ_max counts as singular. Default 1e-12.")
      .rw("max_probe_error", &SubspaceOptions::max_probe_error, "Known-answer solve tolerance. Default 1e-6.")
      .rw("compute_residual", &SubspaceOptions::compute_residual, "Compute the KKT residual. Default True.")
      .rw("reduced_lift_tolerance", &SubspaceOptions::reduced_lift_tolerance,
          "Lift of H̄'s small eigen-directions for the fast path. Default 1e-8.")
      .rw("prepare_constraint_path", &SubspaceOptions::prepare_constraint_path,
          "Prepare set_constraints' fast path (O(p³)) at precompute; False: at the first set_constraints. "
          "Default True.")
      .rw("check_dependent_cd", &SubspaceOptions::check_dependent_cd, "Report Status.DependentCD. Default True.")
      .repr()
      .keyword_init<SubspaceOptions>();
  def_validate<decltype(subspace), SubspaceOptions>(subspace);

  py::class_<ConstraintOptions> constraints(
      m, "ConstraintOptions", "Options of set_constraints (subspace_solver.h); soft=True gives Eq. 18.");
  Fields(constraints, "ConstraintOptions")
      .rw("soft", &ConstraintOptions::soft, "False: hard constraints (Eq. 17); True: soft (Eq. 18).")
      .rw("delta", &ConstraintOptions::delta, "Soft-constraint weight δ. Default 1e3.")
      .rw("rank_tolerance", &ConstraintOptions::rank_tolerance, "Rank threshold of Ā. Default 1e-10.")
      .rw("drop_tolerance", &ConstraintOptions::drop_tolerance, "Round-off entries of A_r zeroed. Default 1e-10.")
      .rw("fast_path", &ConstraintOptions::fast_path, "Use the range-space fast path. Default True.")
      .rw("threads", &ConstraintOptions::threads, "Threads for the dense algebra (0: all). Default 1.")
      .rw("explicit_operators", &ConstraintOptions::explicit_operators, "Always form M_b, M_q, M_Y. Default False.")
      .rw("factored_cost_ratio", &ConstraintOptions::factored_cost_ratio, "Factored-path cost weight. Default 5.")
      .repr()
      .keyword_init<ConstraintOptions>();
  def_validate<decltype(constraints), ConstraintOptions>(constraints);

  py::class_<QuotientOptions> quotient(m, "QuotientOptions",
                                       "Options of the Section 4 analysis and the Theorem 4.10 checker (quotient.h).");
  Fields(quotient, "QuotientOptions")
      .rw("rank_tolerance", &QuotientOptions::rank_tolerance, "Eigenvalues ≤ this·max|λ| count as zero. 1e-10.")
      .rw("symmetry_tolerance", &QuotientOptions::symmetry_tolerance, "‖H − Hᵀ‖_F ≤ this·‖H‖_F. 1e-10.")
      .rw("basis_tolerance", &QuotientOptions::basis_tolerance, "Column-space rank threshold. 1e-10.")
      .rw("kkt_rcond_tolerance", &QuotientOptions::kkt_rcond_tolerance, "Exact KKT solve rcond floor. 1e-14.")
      .rw("roundoff_factor", &QuotientOptions::roundoff_factor, "Slack factor of the violation tests. 100.")
      .rw("threads", &QuotientOptions::threads, "Threads (0: all). 1.")
      .rw("subspace", &QuotientOptions::subspace, "SubspaceOptions of the engine's solve.")
      .rw("constraints", &QuotientOptions::constraints, "ConstraintOptions of the engine's solve.")
      .repr()
      .keyword_init<QuotientOptions>();
  def_validate<decltype(quotient), QuotientOptions>(quotient);
}

// Outcome and the engine's summaries (subspace.h, constraints.h).
void bind_summaries(py::module_& m) {
  py::class_<Outcome>(m, "Outcome", "What every summary starts with: status and message (common.h).")
      .def_readonly("status", &Outcome::status, "Status of the step (starts at Status.NotRun).")
      .def_readonly("message", &Outcome::message, "Message for a person.")
      .def("ok", &Outcome::ok, "Status.Success alone.")
      .def("usable", &Outcome::usable, "Success, or a qualified answer (Status.ConstraintsLeastSquares).")
      .def("brief_report", &Outcome::brief_report,
           "One line: '<status>' or '<status>: <message>' (some summaries say more).")
      .def("full_report", &Outcome::full_report, "Every field, one 'key: value' line each (nested summaries indented).")
      .def(
          "to_dict", [](const Outcome& o) { return report_dict(o.report()); },
          "Every field as a dict under the C++ names: the keys of qpr's JSON reports (docs/formats.md, "
          "'Summaries'); nested summaries as dicts, enums as their names.");

  py::class_<SubspaceSummary, Outcome> subspace(m, "SubspaceSummary", "Result of precompute (subspace.h).");
  Fields(subspace, "SubspaceSummary")
      .listed("status")
      .listed("message")
      .ro("backend_used", &SubspaceSummary::backend_used, "Backend that ran.")
      .ro("n", &SubspaceSummary::n, "Unknowns.")
      .ro("d", &SubspaceSummary::d, "Columns of C.")
      .ro("k", &SubspaceSummary::k, "Columns of D.")
      .ro("rho", &SubspaceSummary::rho, "Augmentation weight (0 on the KKT route).")
      .ro("factor_nonzeros", &SubspaceSummary::factor_nonzeros, "Nonzeros of the factor.")
      .ro("kkt_residual", &SubspaceSummary::kkt_residual, "Relative KKT residual of [N UD] (-1: not computed).")
      .ro("probe_error", &SubspaceSummary::probe_error, "Relative error of the known-answer solve.")
      .ro("s_condition", &SubspaceSummary::s_condition, "λ_max/λ_min of S.")
      .ro("ud_condition", &SubspaceSummary::ud_condition, "λ_max/λ_min of Dᵀ·UD (0 when k = 0).")
      .ro("check_psd_seconds", &SubspaceSummary::check_psd_seconds, "Seconds.")
      .ro("factorize_seconds", &SubspaceSummary::factorize_seconds, "Seconds.")
      .ro("solve_seconds", &SubspaceSummary::solve_seconds, "Seconds.")
      .ro("total_seconds", &SubspaceSummary::total_seconds, "Seconds.")
      .repr();

  py::class_<ConstraintSummary, Outcome> constraints(m, "ConstraintSummary",
                                                     "Result of set_constraints (subspace_solver.h).");
  Fields(constraints, "ConstraintSummary")
      .listed("status")
      .listed("message")
      .ro("m", &ConstraintSummary::m, "Number of constraints.")
      .ro("rank", &ConstraintSummary::rank, "Numerical rank of A_r.")
      .ro("condition", &ConstraintSummary::condition, "σ_max/σ_min of Ā over its rank.")
      .ro("fast_path", &ConstraintSummary::fast_path, "The answer came from the fast path.")
      .ro("factored", &ConstraintSummary::factored, "... with M_q kept factored.")
      .ro("dropped", &ConstraintSummary::dropped, "Entries of A_r zeroed by drop_tolerance.")
      .ro("beyond_subspace", &ConstraintSummary::beyond_subspace,
          "The subspace cannot meet these rows as the full space can (set by the deformer).")
      .ro("seconds", &ConstraintSummary::seconds, "Seconds.")
      .repr();

}

// The analysis summaries (full_solve.h, quotient.h, theorem.h).
void bind_analysis_summaries(py::module_& m) {
  py::class_<FullSolveSummary, Outcome> full(m, "FullSolveSummary", "Result of solve_full (full_solve.h).");
  Fields(full, "FullSolveSummary")
      .listed("status")
      .listed("message")
      .ro("backend_used", &FullSolveSummary::backend_used, "Backend that ran.")
      .ro("kkt_residual", &FullSolveSummary::kkt_residual, "Relative KKT residual of X.")
      .ro("seconds", &FullSolveSummary::seconds, "Seconds.")
      .repr();

  py::class_<FactorSummary, Outcome> factor(m, "FactorSummary", "Result of factor_psd (quotient.h).");
  Fields(factor, "FactorSummary")
      .listed("status")
      .listed("message")
      .ro("n", &FactorSummary::n, "Size of H.")
      .ro("rank", &FactorSummary::rank, "r = rank of H.")
      .ro("nullity", &FactorSummary::nullity, "ν = dim ker H.")
      .ro("lambda_max", &FactorSummary::lambda_max, "Largest eigenvalue.")
      .ro("lambda_min", &FactorSummary::lambda_min, "Smallest eigenvalue.")
      .ro("lambda_min_kept", &FactorSummary::lambda_min_kept, "Smallest eigenvalue kept in L.")
      .ro("residual", &FactorSummary::residual, "‖H − LᵀL‖_F/‖H‖_F.")
      .ro("seconds", &FactorSummary::seconds, "Seconds.")
      .repr();

  py::class_<TheoremSetupSummary, Outcome> setup(m, "TheoremSetupSummary",
                                                 "Result of TheoremChecker.precompute (theorem.h).");
  Fields(setup, "TheoremSetupSummary")
      .listed("status")
      .listed("message")
      .ro("factor", &TheoremSetupSummary::factor, "FactorSummary of H = LᵀL.")
      .ro("subspace", &TheoremSetupSummary::subspace, "SubspaceSummary of the engine's precompute.")
      .ro("design_rank", &TheoremSetupSummary::design_rank, "dim(Span(Ĉ) + Span(D̂)).")
      .ro("seconds", &TheoremSetupSummary::seconds, "Seconds.")
      .repr();
}

}  // namespace

void bind_options(py::module_& m) {
  bind_enums(m);
  bind_option_structs(m);
  bind_summaries(m);
  bind_analysis_summaries(m);
}

}  // namespace qpreduce::python
