// run_scenario: precompute or load, the on-site step, the frames, settle and
// refine (run_scenario.h).
#include "qpreduce/deform/pipeline/run_scenario.h"

#include "qpreduce/deform/energy/arap_energy.h"
#include "qpreduce/deform/io/io_error.h"
#include "qpreduce/deform/mesh/geometry.h"

#include <qpreduce/util/timer.h>

#include <fmt/format.h>

#include <cmath>
#include <fstream>
#include <stdexcept>

namespace qpreduce::deform {

namespace {

// The model from options.cache_path when it holds a matching one, else
// precomputed. Fills the summary's precompute part; false when the
// precompute failed.
bool prepare(const Scenario& scenario, const ScenarioRunOptions& options, const DeformerOptions& deformer_options,
             const ScenarioRunHooks& hooks, Deformer* deformer, ScenarioRunSummary* s) {
  if (!options.cache_path.empty() && std::ifstream(options.cache_path).good()) {
    try {
      s->precompute = deformer->load(options.cache_path, scenario.model, deformer_options);
      s->from_cache = true;
    } catch (const IoError& e) {
      s->cache_message = e.what();
    }
  }
  if (!s->from_cache) {
    s->precompute = deformer->precompute(scenario.model, deformer_options, hooks.progress);
    if (!s->precompute.ok()) {
      s->status = s->precompute.status;
      s->message = "precompute failed: " + s->precompute.message;
      return false;
    }
  }
  if (hooks.prepared) hooks.prepared(*deformer, s->from_cache);
  return true;
}

// The on-site step; false when the set is unusable, or not exact under strict.
bool set_handles(const Scenario& scenario, bool strict, Deformer* deformer, ScenarioRunSummary* s) {
  const Timer timer;
  s->handles = deformer->set_handles(scenario.handles, scenario.constraints);
  s->op_seconds = timer.seconds();
  if (!usable(s->handles.status)) {
    s->status = s->handles.status;
    s->message = "handles: " + s->handles.message;
    return false;
  }
  if (s->handles.status != Status::Success && strict) {
    s->status = s->handles.status;
    s->message = fmt::format("handles: {}: {}; exact handles were asked for (strict)", to_string(s->handles.status),
                             s->handles.message);
    return false;
  }
  return true;
}

// Every frame; false at the first that fails (nothing after it runs).
bool run_frames(const Scenario& scenario, const ScenarioRunHooks& hooks, Deformer* deformer, Vertices* pose,
                ScenarioRunSummary* s) {
  for (size_t f = 0; f < scenario.frames.size(); ++f) {
    const FrameSummary fs = deformer->frame(scenario.frames[f], pose);
    s->frames.push_back(fs);
    if (!usable(fs.status)) {
      s->failed_frame = static_cast<int>(f);
      s->status = fs.status;
      s->message = fmt::format("frame {}: {}: {}", f, to_string(fs.status), fs.message);
      return false;
    }
    s->handle_residual.push_back(handle_residual(scenario, scenario.frames[f], *pose) / s->diagonal);
    if (hooks.frame) hooks.frame(static_cast<int>(f), *pose);
  }
  return true;
}

// The reduced rounds on at the last frame's targets to settle_tolerance;
// *settled is the last frame's pose when the rounds fail (their summary
// says how) or are not needed.
void settle(const Scenario& scenario, const ScenarioRunOptions& options, const DeformerOptions& deformer_options,
            const Vertices& last, Deformer* deformer, Vertices* settled, ScenarioRunSummary* s) {
  s->settled = true;
  const FrameSummary& frame = s->frames.back();
  if (frame.fixed_point_residual <= options.settle_tolerance) {
    s->settle.status = Status::Success;
    s->settle.fixed_point_residual = frame.fixed_point_residual;
    *settled = last;
    return;
  }
  deformer->set_rounds(options.settle_rounds, options.settle_tolerance);
  s->settle = deformer->frame(scenario.frames.back(), settled);
  deformer->set_rounds(deformer_options.iterations, deformer_options.tolerance, deformer_options.time_budget);
  if (!usable(s->settle.status) || settled->rows() != last.rows()) *settled = last;
}

}  // namespace

const char* to_string(ScenarioStage stage) {
  switch (stage) {
    case ScenarioStage::Precompute: return "precompute";
    case ScenarioStage::Handles: return "handles";
    case ScenarioStage::Frames: return "frames";
    case ScenarioStage::Settle: return "settle";
    case ScenarioStage::Refine: return "refine";
    case ScenarioStage::Done: return "done";
  }
  return "unknown";
}

bool ScenarioRunOptions::is_valid(std::string* why) const {
  const auto fail = [why](std::string text) {
    if (why) *why = std::move(text);
    return false;
  };
  if (settle_rounds < 1) return fail(fmt::format("settle_rounds must be ≥ 1, got {}", settle_rounds));
  if (!std::isfinite(settle_tolerance) || settle_tolerance < 0.0)
    return fail(fmt::format("settle_tolerance must be finite and ≥ 0, got {}", settle_tolerance));
  std::string inner;
  if (!deformer.is_valid(&inner)) return fail("deformer: " + inner);
  if (refine && !refine->is_valid(&inner)) return fail("refine: " + inner);
  return true;
}

ScenarioRunSummary run_scenario(const Scenario& scenario, const ScenarioRunOptions& options, Deformer* deformer,
                                ScenarioPoses* poses, const ScenarioRunHooks& hooks) {
  if (deformer == nullptr) throw std::invalid_argument("run_scenario: deformer is null");
  if (scenario.frames.empty()) throw std::invalid_argument("run_scenario: the scenario has no frames");
  std::string why;
  if (!options.is_valid(&why)) throw std::invalid_argument("ScenarioRunOptions: " + why);
  DeformerOptions deformer_options = options.deformer;
  apply_scenario_options(scenario, &deformer_options);

  ScenarioPoses local;
  ScenarioPoses& out = poses ? *poses : local;
  ScenarioRunSummary s;
  s.options = deformer_options;
  s.diagonal = bounding_box_diagonal(scenario.model.V);
  s.stage = ScenarioStage::Precompute;
  if (!prepare(scenario, options, deformer_options, hooks, deformer, &s)) return s;
  s.stage = ScenarioStage::Handles;
  if (!set_handles(scenario, options.strict, deformer, &s)) return s;
  s.stage = ScenarioStage::Frames;
  if (!run_frames(scenario, hooks, deformer, &out.last, &s)) return s;
  if (options.settle || options.refine) {
    s.stage = ScenarioStage::Settle;
    settle(scenario, options, deformer_options, out.last, deformer, &out.settled, &s);
  }
  if (options.refine) {
    s.stage = ScenarioStage::Refine;
    s.refined = true;
    Refiner refiner;
    refiner.precompute(scenario.model, *options.refine);
    s.refine = refiner.refine(scenario.handles, scenario.frames.back(), out.settled, &out.refined);
    if (!s.refine.usable()) {
      s.status = s.refine.status;
      s.message = "refine: " + s.refine.message;
      return s;
    }
  }
  s.arap_energy = arap_energy(scenario.model.V, deformer->elements(), options.refine ? out.refined : out.last);
  s.stage = ScenarioStage::Done;
  s.status = Status::Success;
  return s;
}

void ScenarioRunSummary::add_details(Report* out) const {
  out->add("stage", stage)
      .add("precompute", precompute.report())
      .add("from_cache", from_cache)
      .add("cache_message", cache_message)
      .add("handles", handles.report())
      .add("op_seconds", op_seconds)
      .add("frames", frames.size())
      .add("handle_residual", handle_residual)
      .add("failed_frame", failed_frame)
      .add("settled", settled)
      .add("settle", settle.report())
      .add("refined", refined)
      .add("refine", refine.report())
      .add("diagonal", diagonal)
      .add("arap_energy", arap_energy);
}

}  // namespace qpreduce::deform
