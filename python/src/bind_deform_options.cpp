// qpreduce.deform: the Deformer's options and summaries (deform/deformer/
// deformer.h): ModelKind, ClusterRotationFit, PatchType, DeformerOptions,
// PrecomputeSummary and FrameSummary.
#include "bindings.h"
#include "fields.h"

#include <qpreduce/deform/deformer/deformer.h>

#include <pybind11/stl.h>

namespace qpreduce::python {

using namespace qpreduce::deform;

namespace {

// The enums and the energy parameters.
void bind_deformer_enums(py::module_& m) {
  py::enum_<ModelKind>(m, "ModelKind", "The built-in deformation models (deformer.h).")
      .value("Arap", ModelKind::Arap, "Rotations per cluster (paper Eq. 19).")
      .value("Conformal", ModelKind::Conformal, "Scaled rotations ψ·t, ψ ∈ [1/ψ_max, ψ_max] (Eq. 48–49).");
  py::enum_<ClusterRotationFit>(m, "ClusterRotationFit", "The rotation step of Phase 2 (arap_energy.h).")
      .value("Exact", ClusterRotationFit::Exact, "Block-coordinate descent on E′ (with the Q-corrections).")
      .value("PaperPhase2", ClusterRotationFit::PaperPhase2, "The paper's Eq. 19 (Q dropped).");
  py::enum_<PatchType>(m, "PatchType", "Affine patches (handles.h): Fixed, Rigid or Affine.")
      .value("Fixed", PatchType::Fixed, "Stays at rest.")
      .value("Rigid", PatchType::Rigid, "One rotation and translation.")
      .value("Affine", PatchType::Affine, "One affine map (Eq. 47).");

  py::class_<EnergyParameters> energy(m, "EnergyParameters", "α, β, γ of the modified ARAP energy E′ (Eq. 8–11).");
  Fields(energy, "EnergyParameters")
      .rw("alpha", &EnergyParameters::alpha, "Penalty on the rotation corrections q_k (Eq. 10). Default 0.1.")
      .rw("beta", &EnergyParameters::beta, "Extra penalty on q_k's action on the normal (surfaces). Default 0.1.")
      .rw("gamma", &EnergyParameters::gamma, "Moving-frame penalty γ (Eq. 11); 0 (default) switches it off.")
      .repr()
      .keyword_init<EnergyParameters>();
  def_validate<decltype(energy), EnergyParameters>(energy);

}

// DeformerOptions.
void bind_deformer_option_fields(py::module_& m) {
  py::class_<DeformerOptions> options(m, "DeformerOptions",
                                      "Options of Deformer.precompute (deformer.h); keyword construction.");
  Fields(options, "DeformerOptions")
      .rw("energy", &DeformerOptions::energy, "EnergyParameters (α, β, γ).")
      .rw("model", &DeformerOptions::model, "ModelKind.Arap (default) or ModelKind.Conformal.")
      .rw("conformal_bound", &DeformerOptions::conformal_bound, "ψ_max of the conformal model (> 1). Default 2.")
      .rw("rotational_proxies", &DeformerOptions::rotational_proxies, "Clusters d when not given. Default 27.")
      .rw("linear_proxies", &DeformerOptions::linear_proxies, "Linear proxies when not given. Default 33.")
      .rw("rotation_fit", &DeformerOptions::rotation_fit, "ClusterRotationFit.Exact (default) or PaperPhase2.")
      .rw("iterations", &DeformerOptions::iterations, "Phase 1/Phase 2 rounds per frame (the cap).")
      .rw("tolerance", &DeformerOptions::tolerance, "Stop once fixed_point_residual ≤ this; 0: never.")
      .rw("time_budget", &DeformerOptions::time_budget,
          "Stop a frame's rounds after this many seconds (not the cold start); 0: no budget.")
      .rw("anderson_window", &DeformerOptions::anderson_window, "Anderson acceleration window (0 off, 1–16).")
      .rw("second_order", &DeformerOptions::second_order,
          "Newton steps on stiff point-handle sets instead of rounds (default True).")
      .rw("cold_start_rounds", &DeformerOptions::cold_start_rounds,
          "The first frame after set_handles runs to cold_start_tolerance within this many rounds (a "
          "second-order step counts 10; 0: like the others). Default 500.")
      .rw("cold_start_tolerance", &DeformerOptions::cold_start_tolerance,
          "The first frame's fixed-point residual target. Default 1e-6.")
      .rw("soften_unreachable_handles", &DeformerOptions::soften_unreachable_handles,
          "Handle sets the subspace cannot meet reliably (rank below the full space's, or condition above 1e5) "
          "are met as soft constraints, with the reason in set_handles' message (default True).")
      .rw("global_rotation", &DeformerOptions::global_rotation, "Factor out a global rotation. Default True.")
      .rw("float_rounds", &DeformerOptions::float_rounds, "Phase 2 inputs from float products. Default True.")
      .rw("round_threads", &DeformerOptions::round_threads, "OpenMP threads of a frame's rounds. Default 1.")
      .rw("prepare_onsite", &DeformerOptions::prepare_onsite,
          "Prepare Phase 1's fast path at precompute (a d x d eigendecomposition), so that the first handle set "
          "costs what later ones do; False: at the first set_handles that needs it. Default True.")
      .rw("double_basis", &DeformerOptions::double_basis,
          "Keep the reconstruction basis and w in float64 (twice the memory and bytes per frame) for poses with "
          "double round-off: a rigidly moved scene gives its pose moved to ~1e-15 of the diagonal. Default False.")
      .rw("subspace", &DeformerOptions::subspace, "SubspaceOptions of the engine.")
      .repr()
      .keyword_init<DeformerOptions>();
  def_validate<decltype(options), DeformerOptions>(options);

}

// The summaries of precompute and of a frame.
void bind_deformer_summaries(py::module_& m) {
  py::class_<PrecomputeSummary, Outcome> pre(m, "PrecomputeSummary", "Result of Deformer.precompute / load.");
  Fields(pre, "PrecomputeSummary")
      .listed("status")
      .listed("message")
      .ro("vertices", &PrecomputeSummary::vertices, "n")
      .ro("elements", &PrecomputeSummary::elements, "Rotation elements r.")
      .ro("rotational_proxies", &PrecomputeSummary::rotational_proxies, "d")
      .ro("linear_proxies", &PrecomputeSummary::linear_proxies, "m")
      .ro("patches", &PrecomputeSummary::patches, "s")
      .ro("reduced_size", &PrecomputeSummary::reduced_size, "p = 3m + 12s + 9d")
      .ro("subspace", &PrecomputeSummary::subspace, "The engine's SubspaceSummary.")
      .ro("clustering_seconds", &PrecomputeSummary::clustering_seconds, "")
      .ro("assembly_seconds", &PrecomputeSummary::assembly_seconds, "")
      .ro("subspace_seconds", &PrecomputeSummary::subspace_seconds, "")
      .ro("reduction_seconds", &PrecomputeSummary::reduction_seconds, "")
      .ro("total_seconds", &PrecomputeSummary::total_seconds, "")
      .repr();

  py::class_<FrameSummary, Outcome> frame(m, "FrameSummary", "Result of one Deformer.frame (the quality readout).");
  Fields(frame, "FrameSummary")
      .listed("status")
      .listed("message")
      .ro("iterations", &FrameSummary::iterations, "Rounds run (the alternation's rounds).")
      .ro("stop", &FrameSummary::stop, "RoundStop: the cap, the tolerance or the time budget ended them.")
      .ro("last_change", &FrameSummary::last_change, "‖ΔS‖ of the last Phase 2.")
      .ro("fixed_point_residual", &FrameSummary::fixed_point_residual, "‖ΔS‖/‖S‖ of the last round.")
      .ro("model_energy", &FrameSummary::model_energy, "E′ of the reduced model (accelerated rounds), else NaN.")
      .ro("rejected_steps", &FrameSummary::rejected_steps, "Extrapolations the Anderson safeguard rejected.")
      .ro("second_order", &FrameSummary::second_order, "This frame took Newton steps instead of rounds.")
      .ro("cold_start", &FrameSummary::cold_start,
          "The first frame after set_handles: it ran to cold_start_tolerance (DeformerOptions.cold_start_rounds).")
      .ro("rotation_kept", &FrameSummary::rotation_kept,
          "The rounds in the refitted global rotation ended above the warm start's E′ in the last one, so they "
          "ran again there (iterations counts both).")
      .ro("solve_seconds", &FrameSummary::solve_seconds, "")
      .ro("reconstruct_seconds", &FrameSummary::reconstruct_seconds, "")
      .ro("total_seconds", &FrameSummary::total_seconds, "")
      .repr();
  frame.def_property_readonly(
      "rounds", [](const FrameSummary& s) { return s.iterations; }, "Alias of iterations: the rounds run.");
}

}  // namespace

void bind_deformer_options(py::module_& m) {
  bind_deformer_enums(m);
  bind_deformer_option_fields(m);
  bind_deformer_summaries(m);
}

}  // namespace qpreduce::python
