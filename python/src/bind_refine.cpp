// qpreduce.deform.Refiner: the full-space finish of a reduced pose
// (deform/refine/refine.h). Classic ARAP (Eq. 6) or E′ (Eq. 8–10) by
// local-global rounds, optionally Anderson-accelerated, warm-started from the
// pose given (e.g. Deformer.frame's), re-factoring only when the handle set
// changes. refine releases the GIL and takes the refiner's lock; cancel()
// takes neither, so another thread stops a running refine within one round.
#include "arguments.h"
#include "bindings.h"
#include "fields.h"
#include "locking.h"

#include <qpreduce/deform/refine/refine.h>

#include <pybind11/stl.h>

#include <atomic>
#include <cstdint>
#include <mutex>

namespace qpreduce::python {

namespace {

using namespace qpreduce::deform;

// The Refiner, the model it was precomputed for (its vertex count checks
// poses) and the cancel generation: cancel() bumps it, and a refine stops
// when it differs from the value it started with.
struct PyRefiner {
  Refiner refiner;
  Index vertices = 0;
  std::mutex mutex;
  std::atomic<std::uint64_t> generation{0};
};

void bind_refine_options(py::module_& m) {
  py::class_<RefineOptions> options(m, "RefineOptions", "Options of Refiner (refine.h); keyword construction.");
  Fields(options, "RefineOptions")
      .rw("distance_tolerance", &RefineOptions::distance_tolerance,
          "Stop once the pose is estimated within this of the converged shape (RMS over the vertices / the "
          "bounding-box diagonal; RefineSummary.estimated_distance); finite, ≥ 0. Default 1e-4.")
      .rw("tolerance", &RefineOptions::tolerance,
          "Also stop at this relative energy change or fixed-point residual (can fire in a flat valley); "
          "finite, ≥ 0; 0 (default): not used.")
      .rw("anderson_window", &RefineOptions::anderson_window, "In [0, 16]; 0 = plain local-global. Default 5.")
      .rw("newton_after", &RefineOptions::newton_after,
          "Rounds before trust-region Newton steps on the classic energy replace them; 0 = rounds only. Default 64.")
      .rw("max_iterations", &RefineOptions::max_iterations, "Round limit. Default 20000.")
      .rw("energy", &RefineOptions::energy, "ReferenceEnergy.ClassicArap (default) or ModifiedArap (E′).")
      .rw("parameters", &RefineOptions::parameters, "EnergyParameters of E′ (ModifiedArap only).")
      .rw("backend", &RefineOptions::backend,
          "Factorization of the global step. Default Backend.Auto: CHOLMOD's simplicial LDLᵀ when it separates "
          "by axis (classic ARAP, whole vertices and patches held; the three axes in one sweep), CHOLMOD's "
          "supernodal LLᵀ otherwise.")
      .rw("threads", &RefineOptions::threads,
          "Threads for the rounds; 0 (default): all. The pose does not depend on it.")
      .repr()
      .keyword_init<RefineOptions>();
  def_validate<decltype(options), RefineOptions>(options);

  py::class_<RefineSummary, Outcome> summary(m, "RefineSummary", "Result of Refiner.refine (refine.h).");
  Fields(summary, "RefineSummary")
      .listed("status")
      .listed("message")
      .ro("rounds", &RefineSummary::rounds, "")
      .ro("converged", &RefineSummary::converged, "The tolerance test held (not the round limit).")
      .ro("cancelled", &RefineSummary::cancelled, "cancel() stopped it; the pose is the last accepted one.")
      .ro("refactored", &RefineSummary::refactored, "This call factored the global step (new handle set).")
      .ro("axis_separable", &RefineSummary::axis_separable,
          "One factor serves x, y and z (classic ARAP with whole vertices and patches held).")
      .ro("rejected_steps", &RefineSummary::rejected_steps, "Anderson steps the energy safeguard refused.")
      .ro("newton_steps", &RefineSummary::newton_steps, "Newton steps among the rounds.")
      .ro("cg_iterations", &RefineSummary::cg_iterations, "The Newton steps' Hessian products (one solve each).")
      .ro("seconds", &RefineSummary::seconds, "The rounds' wall time.")
      .ro("setup_seconds", &RefineSummary::setup_seconds, "This call's factorization (0 when reused).")
      .ro("initial_energy", &RefineSummary::initial_energy, "Refined energy of the input pose.")
      .ro("energy", &RefineSummary::energy, "Refined energy (classic or E′) of the result.")
      .ro("arap_energy", &RefineSummary::arap_energy, "Classic ARAP energy (Eq. 6) of the result.")
      .ro("fixed_point_residual", &RefineSummary::fixed_point_residual, "‖G(z) − z‖ / ‖z‖ of the last round.")
      .ro("estimated_distance", &RefineSummary::estimated_distance,
          "How far the result is estimated from the converged shape (RMS / rest diagonal; inf before 2 rounds).")
      .ro("handle_residual", &RefineSummary::handle_residual, "Largest constraint violation.")
      .ro("rms_from_input", &RefineSummary::rms_from_input, "RMS input→result distance / rest diagonal.")
      .ro("max_from_input", &RefineSummary::max_from_input, "Largest input→result distance / rest diagonal.")
      .ro("round_energy", &RefineSummary::round_energy, "Refined energy after each round.")
      .ro("round_seconds", &RefineSummary::round_seconds, "Seconds since the rounds began, after each round.")
      .repr();
}

void bind_refiner_class(py::module_& m) {
  py::class_<PyRefiner>(
      m, "Refiner",
      "Full-space ARAP finish of a reduced pose (refine.h): local-global rounds warm-started from the\n"
      "pose given, one factorization per handle set, reused while only the targets move.\n\n"
      "Threads: refine takes the refiner's lock and releases the GIL; cancel() may be called from any\n"
      "thread at any time and stops the refine running then within one round.")
      .def(py::init([](const DeformableMesh& model, py::handle options) {
             auto self = std::make_unique<PyRefiner>();
             const auto opts = options_arg<RefineOptions>("options", options);
             {
               py::gil_scoped_release release;
               self->refiner.precompute(model, opts);
             }
             self->vertices = model.V.rows();
             return self;
           }),
           py::arg("model"), py::arg("options") = py::none(),
           "Refiner(model, options=None)\n\n"
           "model: a Model (its rest pose, elements and, for E′, clusters); options: RefineOptions.\n"
           "Builds the elements and energy matrices (no factorization yet). ValueError on bad options\n"
           "or a bad model. Releases the GIL.")
      .def(
          "set_options",
          [](PyRefiner& self, const RefineOptions& options) {
            const auto lock = lock_releasing_gil<std::unique_lock<std::mutex>>(self.mutex);
            self.refiner.set_options(options);
          },
          py::arg("options"),
          "set_options(options)\n\nReplaces distance_tolerance, tolerance, anderson_window, newton_after and max_iterations (the energy,\n"
          "parameters and backend stay those of the constructor). ValueError on invalid options.")
      .def_property_readonly(
          "options",
          [](PyRefiner& self) {
            const auto lock = lock_releasing_gil<std::unique_lock<std::mutex>>(self.mutex);
            return self.refiner.options();
          },
          "The RefineOptions in force (a copy).")
      .def(
          "refine",
          [](PyRefiner& self, const Handles& handles, const HandleTargets& targets, py::handle pose, py::handle out) {
            const Index n = self.vertices;
            Vertices input;
            if (!pose.is_none()) input = matrix_view<double>("pose", pose, {n, "n"}, {3, "3"}, false);
            // out, or a new (n, 3) array; matrix_view checks out's dtype, shape and layout.
            const py::object result =
                out.is_none() ? py::array_t<double>({static_cast<py::ssize_t>(n), static_cast<py::ssize_t>(3)})
                              : py::reinterpret_borrow<py::object>(out);
            RowMap<double> target = matrix_view<double>("out", result, {n, "n"}, {3, "3"}, true);
            RefineSummary summary;
            {
              py::gil_scoped_release release;
              const auto lock = std::lock_guard<std::mutex>(self.mutex);
              const std::uint64_t started = self.generation.load();
              Vertices refined;
              summary = self.refiner.refine(handles, targets, input, &refined,
                                            [&] { return self.generation.load() != started; });
              if (refined.rows() == n) target = refined;
            }
            raise_if_unusable(summary, py::cast(summary));
            return py::make_tuple(result, summary);
          },
          py::arg("handles"), py::arg("targets"), py::arg("pose") = py::none(), py::kw_only(),
          py::arg("out") = py::none(),
          "refine(handles, targets, pose=None, *, out=None) -> (V′ (n, 3), RefineSummary)\n\n"
          "Refines pose (n, 3) float64 (None: the rest pose) under handles (Handles) at targets\n"
          "(HandleTargets) to the converged full-space energy, into out (C-contiguous (n, 3) float64)\n"
          "when given. Re-factors only when handles differ from the last call's. ValueError on a bad\n"
          "pose, handles or targets; NumericalError when a factorization or round fails. A cancelled\n"
          "refine returns the last accepted pose with summary.cancelled. Releases the GIL.")
      .def(
          "cancel", [](PyRefiner& self) { ++self.generation; },
          "cancel()\n\nStops the refine running now (from another thread) within one round; no effect on\n"
          "refines started afterwards. Takes no lock.");
}

}  // namespace

void bind_refiner(py::module_& deform) {
  bind_refine_options(deform);
  bind_refiner_class(deform);
}

}  // namespace qpreduce::python
