// qpreduce.deform.run_scenario: a whole scenario in one call
// (deform/pipeline/run_scenario.h), the pipeline `qpr deform` runs:
// precompute or cache, the on-site step, every frame, settle, refine.
#include "arguments.h"
#include "bindings.h"
#include "fields.h"

#include <qpreduce/deform/pipeline/run_scenario.h>

#include <pybind11/stl.h>

namespace qpreduce::python {

namespace {

using namespace qpreduce::deform;

void bind_run_options(py::module_& m) {
  py::enum_<ScenarioStage>(m, "ScenarioStage", "Where run_scenario stopped: the stage that failed, or Done.")
      .value("Precompute", ScenarioStage::Precompute)
      .value("Handles", ScenarioStage::Handles)
      .value("Frames", ScenarioStage::Frames)
      .value("Settle", ScenarioStage::Settle)
      .value("Refine", ScenarioStage::Refine)
      .value("Done", ScenarioStage::Done);

  py::class_<ScenarioRunOptions> options(m, "ScenarioRunOptions",
                                         "Options of run_scenario (run_scenario.h); keyword construction.");
  Fields(options, "ScenarioRunOptions")
      .rw("deformer", &ScenarioRunOptions::deformer,
          "DeformerOptions; the scenario's own overrides (a scene's α, β, γ, ψ, model, …) apply on top.")
      .rw("cache_path", &ScenarioRunOptions::cache_path,
          "Load the precomputed model from this Deformer.save file when it matches; '' (default): precompute.")
      .rw("strict", &ScenarioRunOptions::strict,
          "A handle set met only in the least-squares sense ends the run. Default False.")
      .rw("settle", &ScenarioRunOptions::settle,
          "After the last frame, run the reduced rounds on to settle_tolerance. Implied by refine. Default False.")
      .rw("settle_rounds", &ScenarioRunOptions::settle_rounds, "At most this many settle rounds (≥ 1). Default 500.")
      .rw("settle_tolerance", &ScenarioRunOptions::settle_tolerance,
          "Relative fixed-point residual the settle runs to (finite, ≥ 0). Default 1e-6.")
      .rw("refine", &ScenarioRunOptions::refine,
          "RefineOptions: refine the settled pose in full space; None (default): no refine.")
      .repr()
      .keyword_init<ScenarioRunOptions>();
  def_validate<decltype(options), ScenarioRunOptions>(options);

  py::class_<ScenarioRunSummary, Outcome> summary(m, "ScenarioRunSummary", "Result of run_scenario.");
  Fields(summary, "ScenarioRunSummary")
      .listed("status")
      .listed("message")
      .ro("stage", &ScenarioRunSummary::stage, "ScenarioStage.Done, or the stage that failed.")
      .ro("options", &ScenarioRunSummary::options,
          "DeformerOptions as the run used them: options.deformer with the scenario's overrides.")
      .ro("precompute", &ScenarioRunSummary::precompute, "PrecomputeSummary of the precompute or the load.")
      .ro("from_cache", &ScenarioRunSummary::from_cache, "The model was loaded from cache_path.")
      .ro("cache_message", &ScenarioRunSummary::cache_message, "Why a cache given was not used ('' otherwise).")
      .ro("handles", &ScenarioRunSummary::handles, "ConstraintSummary of the on-site step.")
      .ro("op_seconds", &ScenarioRunSummary::op_seconds, "The on-site step's wall time.")
      .ro("frames", &ScenarioRunSummary::frames, "List of FrameSummary, one per frame run.")
      .ro("handle_residual", &ScenarioRunSummary::handle_residual,
          "Per frame: the largest handle residual / the rest pose's bounding-box diagonal.")
      .ro("failed_frame", &ScenarioRunSummary::failed_frame, "The frame that failed (stage Frames), else -1.")
      .ro("settled", &ScenarioRunSummary::settled, "The settle stage ran.")
      .ro("settle", &ScenarioRunSummary::settle, "FrameSummary of the settle (0 rounds: the last frame was there).")
      .ro("refined", &ScenarioRunSummary::refined, "The refine stage ran.")
      .ro("refine", &ScenarioRunSummary::refine, "RefineSummary of the refine.")
      .ro("diagonal", &ScenarioRunSummary::diagonal, "Bounding-box diagonal of the rest pose.")
      .ro("arap_energy", &ScenarioRunSummary::arap_energy,
          "Classic ARAP energy of the pose shown (the refined one with refine, else the last frame's).")
      .repr();
}

}  // namespace

void bind_pipeline(py::module_& deform) {
  bind_run_options(deform);
  deform.def(
      "run_scenario",
      [](const Scenario& scenario, py::handle options) {
        const auto opts = options_arg<ScenarioRunOptions>("options", options);
        ScenarioRunSummary summary;
        ScenarioPoses poses;
        {
          py::gil_scoped_release release;
          Deformer deformer;
          summary = run_scenario(scenario, opts, &deformer, &poses);
        }
        raise_if_unusable(summary, py::cast(summary));
        py::dict out;
        out["last"] = py::cast(poses.last);
        out["settled"] = poses.settled.size() > 0 ? py::cast(poses.settled) : py::none();
        out["refined"] = poses.refined.size() > 0 ? py::cast(poses.refined) : py::none();
        return py::make_tuple(out, summary);
      },
      py::arg("scenario"), py::arg("options") = py::none(),
      "run_scenario(scenario, options=None) -> (poses, ScenarioRunSummary)\n\n"
      "Runs a Scenario as `qpr deform` does: precompute (or load options.cache_path), the on-site\n"
      "step, every frame, then settle and refine when the options ask. poses: a dict with 'last',\n"
      "'settled' and 'refined' (n, 3) float64 arrays (None for a stage that did not run).\n"
      "ValueError on bad options or a scenario without frames; NumericalError naming the stage\n"
      "(summary.stage) when one fails. Releases the GIL.");
}

}  // namespace qpreduce::python
