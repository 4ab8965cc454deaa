// qpreduce::deform — a whole deformation scenario in one call: precompute
// (or load a cached model), the on-site step for the scenario's handles,
// every frame, then, when asked, the reduced rounds run on to their fixed
// point at the last frame's targets ("settle") and the full-space finish
// from there (refine.h). `qpr deform`, `qpr demo`, `qpr compare`, the
// viewer's headless mode and Python's deform.run_scenario call it; they
// parse, print and write files.
//
// Usage:
//   ScenarioRunOptions o;
//   o.refine = RefineOptions{};              // settle, then refine
//   Deformer deformer;
//   ScenarioPoses poses;
//   ScenarioRunSummary s = run_scenario(scenario, o, &deformer, &poses);
//   if (!s.ok()) … s.stage, s.message …      // poses.refined: the finished shape
#pragma once

#include "qpreduce/deform/deformer/deformer.h"
#include "qpreduce/deform/io/scenario.h"
#include "qpreduce/deform/refine/refine.h"

#include <functional>
#include <optional>
#include <string>
#include <vector>

namespace qpreduce::deform {

struct ScenarioRunOptions {
  // The deformer's options; the scenario's own overrides (a scene's α, β,
  // γ, ψ, model, iterations, proxy counts) are applied on top
  // (apply_scenario_options).
  DeformerOptions deformer;
  // Non-empty: the precomputed model is loaded from this Deformer::save file
  // when it exists and was made from the same inputs; otherwise it is
  // precomputed (the run does not write it: ScenarioRunHooks::prepared can).
  std::string cache_path;
  // A handle set the subspace meets only in the least-squares sense
  // (ConstraintSummary status other than Success) ends the run.
  bool strict = false;
  // After the last frame, run the reduced rounds on at its targets until the
  // relative fixed-point residual is settle_tolerance (at most settle_rounds
  // rounds). A last frame already there is its own settled pose. Implied by
  // refine. settle_rounds ≥ 1; settle_tolerance finite and ≥ 0.
  bool settle = false;
  int settle_rounds = 500;
  double settle_tolerance = 1e-6;
  // Set: refine the settled pose in full space (Refiner) under the
  // scenario's handles at the last frame's targets.
  std::optional<RefineOptions> refine;

  // False with a reason, e.g. "settle_rounds must be ≥ 1, got 0".
  bool is_valid(std::string* why) const;
};

// Calls a run makes to its caller on the way (each optional).
struct ScenarioRunHooks {
  // Precompute progress (Deformer::precompute).
  ProgressFn progress;
  // After the model is ready, before the on-site step: `from_cache` when it
  // was loaded from ScenarioRunOptions::cache_path (e.g. save it there when
  // it was not).
  std::function<void(const Deformer& deformer, bool from_cache)> prepared;
  // After each frame f (0-based) with its pose (n × 3).
  std::function<void(int frame, const Vertices& pose)> frame;
};

// Where a run stopped: the stage that failed, or Done.
enum class ScenarioStage { Precompute, Handles, Frames, Settle, Refine, Done };
const char* to_string(ScenarioStage stage);

struct ScenarioRunSummary : Outcome {  // Success when every stage ran
  ScenarioStage stage = ScenarioStage::Precompute;  // Done, or the stage that failed
  // The deformer's options as the run used them: ScenarioRunOptions::deformer
  // with the scenario's overrides (apply_scenario_options).
  DeformerOptions options;
  PrecomputeSummary precompute;        // of the precompute, or of the load
  bool from_cache = false;             // loaded from ScenarioRunOptions::cache_path
  std::string cache_message;           // why a cache was not used ("" when it was, or none was given)
  ConstraintSummary handles;           // the on-site step (Deformer::set_handles)
  double op_seconds = 0.0;             // its wall time
  std::vector<FrameSummary> frames;    // one per frame run (the report: their count)
  // Per frame: the largest handle residual over the bounding-box diagonal
  // of the rest pose (handle_residual).
  std::vector<double> handle_residual;
  int failed_frame = -1;               // the frame that failed (stage Frames)
  bool settled = false;                // the settle stage ran (ScenarioRunOptions::settle or refine)
  FrameSummary settle;                 // its rounds (0: the last frame was at settle_tolerance already)
  bool refined = false;                // the refine stage ran
  RefineSummary refine;
  double diagonal = 0.0;               // bounding-box diagonal of the rest pose
  // Classic ARAP energy (arap_energy.h) of the pose shown: the refined one
  // with refine, else the last frame's.
  double arap_energy = 0.0;

 protected:
  void add_details(Report* out) const override;
};

// The poses of a run (n × 3 each; empty when the stage did not run).
struct ScenarioPoses {
  Vertices last;     // the last frame's
  Vertices settled;  // the last frame's fixed point (settle)
  Vertices refined;  // the full-space finish (refine)
};

// Runs `scenario` through `deformer` (which keeps the model, the handle set
// and the rotations after the run, for the caller to read) and writes the
// poses to *poses when given. The deformer runs with options.deformer and
// the scenario's overrides (apply_scenario_options(scenario, ·)).
// Throws std::invalid_argument on invalid options or a null deformer (and
// as Deformer::precompute, set_handles and frame on bad input). A failed
// stage comes back as the summary's status and message, with `stage`
// naming it; the stages before it are filled in. The deformer's round
// settings are `options.deformer`'s again after the settle stage.
ScenarioRunSummary run_scenario(const Scenario& scenario, const ScenarioRunOptions& options, Deformer* deformer,
                                ScenarioPoses* poses = nullptr, const ScenarioRunHooks& hooks = {});

}  // namespace qpreduce::deform
