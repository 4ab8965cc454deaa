// qpreduce.deform: the reduced ARAP deformer (deform/deformer/deformer.h; its
// options and summaries are in bind_deform_options.cpp): the model, the
// handles and the targets. Each Python Deformer holds the C++ Deformer and a
// mutex every call takes (frames change the pose, so no call is const); the
// long calls (precompute, load, save, set_handles, frame) release the GIL, so
// two deformers run in two threads at once.
#include "arguments.h"
#include "bindings.h"
#include "fields.h"
#include "handles_arg.h"
#include "locking.h"

#include <qpreduce/deform/deformer/deformer.h>
#include <qpreduce/deform/io/io_error.h>
#include <qpreduce/deform/io/scenario.h>

#include <fmt/format.h>
#include <pybind11/stl.h>

#include <atomic>
#include <mutex>
#include <thread>
#include <type_traits>

namespace qpreduce::python {

namespace {

using namespace qpreduce::deform;

// The Deformer and its inputs: the model and options it was built from (load
// needs them), the handles of the last set_handles, the targets of a frame
// (kept so that a frame allocates nothing once their sizes are known).
struct PyDeformer {
  Deformer deformer;
  DeformableMesh model;
  DeformerOptions options;
  Handles handles;
  HandleTargets targets;
  FrameSummary last_frame;
  // Why the last set_handles failed ("" when it held): frames are refused
  // until a handle set holds, so a failure never leaves a stale set in use.
  std::string handles_failed;
  bool handles_set = false;  // a set_handles held since the last precompute or load
  // Whether the handles pin a vertex twice or inside a fixed patch: only
  // then can a frame's targets fail check_handle_targets (kept off the
  // frame path otherwise).
  bool pins_to_check = false;
  // The handle set holds only in the least-squares sense (set_handles said
  // ConstraintsLeastSquares): each frame then measures how far its handles
  // end from their targets and warns (or raises under strict).
  bool least_squares = false;
  std::string least_squares_reason;
  bool least_squares_beyond_subspace = false;  // ConstraintSummary::beyond_subspace of that set
  bool strict = false;
  double diagonal = 0.0;  // of the model's rest bounding box (set with the model)
  std::mutex mutex;
  // The thread running precompute, while it calls the progress callable:
  // a call from there would wait for the lock its own thread holds.
  std::atomic<std::thread::id> reporting{};

  void refuse_reentry() const {
    if (reporting.load() == std::this_thread::get_id()) {
      throw py::value_error("Deformer: called from its own precompute's progress callable");
    }
  }
  // After a precompute or load that succeeded: the C++ deformer starts
  // without a handle set (a failed one keeps the last, and so does this).
  void forget_handles() {
    handles = Handles{};
    targets = HandleTargets{};
    handles_failed.clear();
    handles_set = false;
    pins_to_check = false;
    least_squares = false;
    least_squares_beyond_subspace = false;
  }
  std::unique_lock<std::mutex> lock() {
    refuse_reentry();
    return lock_releasing_gil<std::unique_lock<std::mutex>>(mutex);
  }
};

// What to do about a least-squares handle set: a set the subspace cannot
// follow needs its vertices named at precompute; a dependent one (a vertex
// held twice) needs one target per vertex.
std::string least_squares_advice(bool beyond_subspace) {
  if (beyond_subspace) {
    return "Name point-handle vertices at precompute to meet them exactly: deform.ArapSolver(V, F, b)";
  }
  return "Give each vertex one target (its targets are averaged now)";
}

// After a frame of a least-squares handle set: warns (raises under strict)
// when its handles end more than 10⁻⁶ of the diagonal from their targets,
// saying how far.
void warn_if_off_target(PyDeformer& self, const RowMap<double>& pose, py::handle summary) {
  const double diagonal = self.diagonal;
  const double off = handle_residual(self.model, self.handles, self.targets, pose);
  if (!(off > 1e-6 * diagonal)) return;
  warn_or_raise(fmt::format("Deformer.frame: the handles end {:.2e} of the bounding-box diagonal from their targets "
                            "(the set holds only in the least-squares sense: {}). {}",
                            off / diagonal, self.least_squares_reason, least_squares_advice(self.least_squares_beyond_subspace)),
                self.strict, self.last_frame, summary);
}

// True when a single-vertex point handle pins a vertex another one pins too,
// or a vertex inside a fixed patch (PyDeformer::pins_to_check).
bool pins_to_check(const DeformableMesh& model, const Handles& handles) {
  std::vector<char> pinned(static_cast<size_t>(model.V.rows()), 0);
  for (const PointHandle& ph : handles.points) {
    if (ph.vertices.size() != 1 || !ph.weights.empty()) continue;
    const Index v = ph.vertices[0];
    if (v < 0 || v >= model.V.rows()) continue;
    const int patch = static_cast<size_t>(v) < model.patch_of_vertex.size() ? model.patch_of_vertex[v] : -1;
    if (pinned[static_cast<size_t>(v)]++ ||
        (patch >= 0 && model.patch_types[static_cast<size_t>(patch)] == PatchType::Fixed)) {
      return true;
    }
  }
  return false;
}

// Thrown through precompute when the progress callable raised; the Python
// error is back in the interpreter's error indicator.
struct ProgressRaised {};

ProgressFn progress_arg(py::handle progress) {
  if (progress.is_none()) return {};
  if (!PyCallable_Check(progress.ptr())) {
    throw py::type_error("progress: expected a callable progress(stage: str, fraction: float) or None, got " +
                         py::str(py::type::of(progress).attr("__name__")).cast<std::string>());
  }
  return [callable = py::reinterpret_borrow<py::object>(progress)](const std::string& stage, double fraction) {
    py::gil_scoped_acquire gil;
    try {
      callable(stage, fraction);
    } catch (py::error_already_set& error) {
      error.restore();
      throw ProgressRaised{};
    }
  };
}

// The fields of a DeformableMesh from NumPy: V (n, 3) and elements (m, 3) or
// (m, 4).
DeformableMesh model_arg(py::handle V, py::handle elements, py::handle clusters, py::handle patch_of_vertex,
                         py::handle patch_types) {
  const auto convert = py::module_::import("qpreduce._convert");
  DeformableMesh model;
  model.V = convert.attr("as_rows")("V", V, py::make_tuple(3), "n", "float64").cast<Vertices>();
  const Index n = model.V.rows();
  const py::object E = convert.attr("as_rows")("elements", elements, py::make_tuple(3, 4), "m", "int32");
  if (E.attr("shape").cast<py::tuple>()[1].cast<int>() == 3) {
    model.F = E.cast<Triangles>();
  } else {
    model.T = E.cast<Tetrahedra>();
  }
  const Index r = model.is_tet() ? model.T.rows() : n;
  if (!clusters.is_none()) {
    model.clusters =
        convert.attr("as_labels")("clusters", clusters, r, model.is_tet() ? "m" : "n").cast<std::vector<int>>();
  }
  if (!patch_of_vertex.is_none()) {
    model.patch_of_vertex =
        convert.attr("as_labels")("patch_of_vertex", patch_of_vertex, n, "n").cast<std::vector<int>>();
  }
  if (!patch_types.is_none()) {
    try {
      model.patch_types = patch_types.cast<std::vector<PatchType>>();
    } catch (const py::cast_error&) {
      throw py::type_error("patch_types: expected a list of qpreduce.deform.PatchType, got " +
                           py::repr(patch_types).cast<std::string>());
    }
  }
  return model;
}

void bind_model(py::module_& m) {
  py::class_<DeformableMesh>(m, "Model",
                             "What precompute needs (handles.h): rest positions V (n, 3), triangles F (m, 3)\n"
                             "or tetrahedra T (m, 4), optional rotational clusters (one per rotation element:\n"
                             "vertex for surfaces, tet for solids) and affine patches.")
      .def(py::init(&model_arg), py::arg("V"), py::arg("elements"), py::arg("clusters") = py::none(),
           py::arg("patch_of_vertex") = py::none(), py::arg("patch_types") = py::none(),
           "Model(V, elements, clusters=None, patch_of_vertex=None, patch_types=None)\n\n"
           "V: (n, 3) real; elements: (m, 3) triangles or (m, 4) tetrahedra, integers; clusters: (n,)\n"
           "or (m,) labels; patch_of_vertex: (n,), −1 for a free vertex; patch_types: list of PatchType.\n"
           "Copied. TypeError/ValueError naming the argument on a wrong dtype, shape or NaN.")
      .def_readonly("V", &DeformableMesh::V, "(n, 3) rest positions")
      .def_readonly("F", &DeformableMesh::F, "(m, 3) triangles, or (0, 3)")
      .def_readonly("T", &DeformableMesh::T, "(m, 4) tetrahedra, or (0, 4)")
      .def_readonly("clusters", &DeformableMesh::clusters, "Cluster per rotation element, or [].")
      .def_readonly("patch_of_vertex", &DeformableMesh::patch_of_vertex, "(n) patch per vertex (−1 free), or [].")
      .def_readonly("patch_types", &DeformableMesh::patch_types, "PatchType per patch.")
      .def_property_readonly("is_tet", &DeformableMesh::is_tet)
      .def("__repr__", [](const DeformableMesh& model) {
        return "Model(n=" + std::to_string(model.V.rows()) + ", " +
               (model.is_tet() ? "tets=" + std::to_string(model.T.rows())
                               : "triangles=" + std::to_string(model.F.rows())) +
               ", patches=" + std::to_string(model.patch_types.size()) + ")";
      });
  m.def(
      "handle_residual",
      [](const DeformableMesh& model, const Handles& handles, const HandleTargets& targets, py::handle deformed) {
        const auto Vp = matrix_view<double>("deformed", deformed, {model.V.rows(), "n"}, {3, "3"}, false);
        const Vertices copy = Vp;
        py::gil_scoped_release release;
        return handle_residual(model, handles, targets, copy);
      },
      py::arg("model"), py::arg("handles"), py::arg("targets"), py::arg("deformed"),
      "handle_residual(model, handles, targets, deformed) -> float\n\n"
      "Largest distance between where the handles are in deformed (n, 3) and their targets.");
}

template <typename Summary>
Summary checked(Summary summary) {
  if (!summary.usable()) raise_if_unusable(summary, py::cast(summary));
  return summary;
}

// Fills the kept HandleTargets from a frame's arguments (no allocation once
// the sizes are known).
void targets_arg(PyDeformer& self, py::handle targets, py::handle patch_transforms) {
  if (py::isinstance<HandleTargets>(targets)) {
    if (!patch_transforms.is_none()) throw py::type_error("patch_transforms: give them in the HandleTargets object");
    self.targets = targets.cast<const HandleTargets&>();
    return;
  }
  const Index h = static_cast<Index>(self.handles.points.size());
  if (targets.is_none()) {
    if (h > 0)
      throw py::type_error("targets: expected a numpy.ndarray of float64 with shape (h, 3) = (" + std::to_string(h) +
                           ", 3), got None");
    self.targets.points.resize(0, 3);
  } else {
    self.targets.points = matrix_view<double>("targets", targets, {h, "h"}, {3, "3"}, false);
  }
  const Index s = static_cast<Index>(self.handles.patches.size());
  self.targets.patch_transforms.resize(s);
  if (s == 0 && patch_transforms.is_none()) return;
  if (patch_transforms.is_none()) {
    throw py::type_error("patch_transforms: expected a numpy.ndarray of float64 with shape (s, 3, 4) = (" +
                         std::to_string(s) + ", 3, 4), got None");
  }
  const std::string expected =
      "patch_transforms: expected a numpy.ndarray of float64 with shape (s, 3, 4) = (" + std::to_string(s) + ", 3, 4)";
  if (!py::isinstance<py::array>(patch_transforms)) {
    throw py::type_error(expected + ", got " +
                         py::str(py::type::of(patch_transforms).attr("__name__")).cast<std::string>());
  }
  const auto array = py::reinterpret_borrow<py::array>(patch_transforms);
  if (array.ndim() != 3 || array.shape(0) != s || array.shape(1) != 3 || array.shape(2) != 4) {
    throw py::value_error(expected + ", got " + py::str(patch_transforms.attr("shape")).cast<std::string>());
  }
  const auto flat = matrix_view<double>("patch_transforms", array.attr("reshape")(s, 12), {s, "s"}, {12, "12"}, false);
  for (Index p = 0; p < s; ++p) {
    self.targets.patch_transforms[p] = Eigen::Map<const Eigen::Matrix<double, 3, 4, Eigen::RowMajor>>(&flat(p, 0));
  }
}

// The constructor.
void bind_deformer_setup(py::class_<PyDeformer>& cls) {
  cls
      .def(
          py::init([](py::handle V, py::handle elements, py::handle options, py::handle clusters,
                      py::handle patch_of_vertex, py::handle patch_types, bool strict) {
            auto self = std::make_unique<PyDeformer>();
            self->strict = strict;
            if (py::isinstance<DeformableMesh>(V)) {  // Deformer(model, options)
              if (!options.is_none() || !clusters.is_none() || !patch_of_vertex.is_none() || !patch_types.is_none()) {
                throw py::type_error("Deformer(model, options=None): the model carries the mesh, clusters and patches");
              }
              self->model = V.cast<DeformableMesh>();
              options = elements;
            } else {
              self->model = model_arg(V, elements, clusters, patch_of_vertex, patch_types);
            }
            self->options = options_arg<DeformerOptions>("options", options);
            const Vertices& rest = self->model.V;
            if (rest.rows() > 0) self->diagonal = (rest.colwise().maxCoeff() - rest.colwise().minCoeff()).norm();
            return self;
          }),
          py::arg("V"), py::arg("elements") = py::none(), py::arg("options") = py::none(), py::kw_only(),
          py::arg("clusters") = py::none(), py::arg("patch_of_vertex") = py::none(),
          py::arg("patch_types") = py::none(), py::arg("strict") = false,
          "Deformer(V, elements, options=None, *, clusters=None, patch_of_vertex=None, patch_types=None,\n"
          "strict=False)\n"
          "Deformer(model, options=None)\n\n"
          "V: (n, 3) rest positions; elements: (m, 3) triangles or (m, 4) tetrahedra (see Model);\n"
          "options: DeformerOptions. Nothing is computed until precompute (or load).");
}

// precompute, save and load.
void bind_deformer_precompute(py::class_<PyDeformer>& cls) {
  cls
      .def(
          "precompute",
          [](PyDeformer& self, py::handle progress) {
            const ProgressFn fn = progress_arg(progress);
            self.refuse_reentry();
            PrecomputeSummary summary;
            {
              py::gil_scoped_release release;
              std::lock_guard<std::mutex> lock(self.mutex);
              self.reporting = std::this_thread::get_id();
              try {
                summary = self.deformer.precompute(self.model, self.options, fn);
              } catch (const ProgressRaised&) {
                self.reporting = std::thread::id{};
                py::gil_scoped_acquire gil;
                throw py::error_already_set();
              } catch (...) {
                self.reporting = std::thread::id{};
                throw;
              }
              self.reporting = std::thread::id{};
              if (summary.usable()) self.forget_handles();
            }
            return checked(summary);
          },
          py::arg("progress") = py::none(),
          "precompute(progress=None) -> PrecomputeSummary\n\n"
          "Clusters, proxies, one factorization and the reduction (O(n) memory for B, 3n×p float).\n"
          "progress(stage: str, fraction: float) is called between stages (an exception it raises\n"
          "aborts the precompute and leaves the deformer as it was; a call of this deformer from it\n"
          "raises ValueError: the precompute holds its lock). Raises ValueError on a bad model\n"
          "or options, NumericalError when a numerical step fails. Releases the GIL.")
      .def(
          "save",
          [](PyDeformer& self, const std::string& path) {
            self.refuse_reentry();
            py::gil_scoped_release release;
            std::lock_guard<std::mutex> lock(self.mutex);
            self.deformer.save(path);
          },
          py::arg("path"),
          "save(path)\n\nWrites the precomputed model (binary, CRC-checked, docs/formats.md). Raises\n"
          "qpreduce.deform.IoError when it cannot be written, ValueError before precompute.")
      .def(
          "load",
          [](PyDeformer& self, const std::string& path) {
            self.refuse_reentry();
            PrecomputeSummary summary;
            {
              py::gil_scoped_release release;
              std::lock_guard<std::mutex> lock(self.mutex);
              summary = self.deformer.load(path, self.model, self.options);
              if (summary.usable()) self.forget_handles();
            }
            return checked(summary);
          },
          py::arg("path"),
          "load(path) -> PrecomputeSummary\n\nReads a model written by save instead of precomputing; the\n"
          "deformer's model and options must be those it was made from (IoError otherwise).");
}

// set_handles (the on-site step) and frame.
void bind_deformer_onsite(py::class_<PyDeformer>& cls) {
  cls
      .def(
          "set_handles",
          [](PyDeformer& self, py::handle handles, py::handle patches, py::handle options) {
            self.refuse_reentry();
            Handles h = handles_arg(handles, patches);
            const auto opts = options_arg<ConstraintOptions>("options", options);
            ConstraintSummary summary;
            {
              py::gil_scoped_release release;
              std::lock_guard<std::mutex> lock(self.mutex);
              self.handles_failed = "set_handles raised";
              summary = self.deformer.set_handles(h, opts);
              self.handles_failed = summary.usable() ? "" : summary.message;
              self.handles_set = summary.usable();
              self.handles = std::move(h);
              self.targets = HandleTargets{};  // the targets of the last set no longer apply
              self.pins_to_check = pins_to_check(self.model, self.handles);
              self.least_squares = summary.status == Status::ConstraintsLeastSquares;
              self.least_squares_reason = summary.message;
              self.least_squares_beyond_subspace = summary.beyond_subspace;
            }
            py::object result = py::cast(checked(summary));
            if (self.least_squares) {
              warn_or_raise("Deformer.set_handles: the frames will meet these handles only in the least-squares "
                            "sense (" + summary.message + "). " + least_squares_advice(summary.beyond_subspace),
                            self.strict, summary, result);
            }
            return result;
          },
          py::arg("handles") = py::none(), py::kw_only(), py::arg("patches") = py::none(),
          py::arg("options") = py::none(),
          "set_handles(handles=None, *, patches=None, options=None) -> ConstraintSummary\n\n"
          "The on-site step. handles: a Handles, or a sequence whose items are vertex indices,\n"
          "(vertices, weights) pairs or PointHandles (h point handles); patches: prescribed patch\n"
          "indices (s); options: ConstraintOptions (soft=True for soft handles). Fixed patches always\n"
          "hold. Raises ValueError on indices out of range, NumericalError when the reduced\n"
          "constraints fail. Cost independent of n; releases the GIL.")
      .def(
          "frame",
          [](PyDeformer& self, py::handle targets, py::handle out, py::handle patch_transforms) {
            const auto lock = self.lock();
            if (!self.deformer.ready()) throw py::value_error("Deformer.frame: call precompute and set_handles first");
            if (!self.handles_failed.empty()) {
              throw py::value_error("Deformer.frame: the last set_handles failed (" + self.handles_failed +
                                    "); call set_handles with a handle set that holds");
            }
            if (!self.handles_set) {
              throw py::value_error(
                  "Deformer.frame: call set_handles first (a precompute or load starts without handles)");
            }
            targets_arg(self, targets, patch_transforms);
            const Index n = self.deformer.vertex_count();
            py::array_t<double> result = out.is_none() ? py::array_t<double>(std::vector<py::ssize_t>{n, 3})
                                                       : py::reinterpret_borrow<py::array_t<double>>(out);
            auto view = matrix_view<double>("out", result, {n, "n"}, {3, "3"}, true);
            // Arguments first, then whether the targets can hold at all.
            if (self.pins_to_check) check_handle_targets(self.model, self.handles, self.targets, -1, "Deformer.frame");
            {
              py::gil_scoped_release release;
              self.last_frame = self.deformer.frame(self.targets, Eigen::Map<Vertices>(view.data(), n, 3));
            }
            checked(self.last_frame);
            if (self.least_squares && self.last_frame.ok()) warn_if_off_target(self, view, py::cast(self.last_frame));
            return result;
          },
          py::arg("targets") = py::none(), py::arg("out") = py::none(), py::kw_only(),
          py::arg("patch_transforms") = py::none(),
          "frame(targets=None, out=None, *, patch_transforms=None) -> V′ (n, 3)\n\n"
          "One pose: rounds of Phase 1/Phase 2 warm-started from the last frame, then the\n"
          "reconstruction. targets: (h, 3) float64, one row per point handle (or a HandleTargets);\n"
          "patch_transforms: (s, 3, 4) float64, [A | t] per prescribed patch; out: (n, 3) float64\n"
          "C-contiguous, written in place and returned (no copy); None makes a new array. The\n"
          "summary is in .last_frame. Raises TypeError/ValueError naming a bad argument,\n"
          "NumericalError when the rounds fail. Releases the GIL.");
}

// The last frame, the rounds' settings and the sizes.
void bind_deformer_rounds(py::class_<PyDeformer>& cls) {
  cls
      .def_property_readonly(
          "last_frame", [](PyDeformer& self) { return self.lock(), self.last_frame; },
          "FrameSummary of the last frame: iterations (rounds), fixed_point_residual, model_energy, ...")
      .def(
          "reset_pose", [](PyDeformer& self) { return self.lock(), self.deformer.reset_pose(); },
          "Back to the rest rotations.")
      .def(
          "set_rounds",
          [](PyDeformer& self, int iterations, double tolerance, double time_budget) {
            const auto lock = self.lock();
            self.deformer.set_rounds(iterations, tolerance, time_budget);
          },
          py::arg("iterations"), py::arg("tolerance") = 0.0, py::arg("time_budget") = 0.0,
          "set_rounds(iterations, tolerance=0.0, time_budget=0.0)\n\nReplaces the cap on rounds per frame (≥ 1), "
          "the early stop and the time budget in seconds (set_rounds(8): the paper's fixed 8 rounds).")
      .def(
          "set_round_threads",
          [](PyDeformer& self, int threads) { return self.lock(), self.deformer.set_round_threads(threads); },
          py::arg("threads"), "OpenMP threads of a frame's rounds (0: all).")
      .def_property_readonly(
          "ready", [](PyDeformer& s) { return s.lock(), s.deformer.ready() && s.handles_failed.empty(); },
          "precompute (or load) succeeded and the last set_handles since then, if any, held; frame runs\n"
          "once a set_handles has.")
      .def_property_readonly(
          "vertex_count", [](PyDeformer& s) { return s.lock(), s.deformer.vertex_count(); }, "n")
      .def_property_readonly(
          "rotational_proxies", [](PyDeformer& s) { return s.lock(), s.deformer.rotational_proxies(); }, "d")
      .def_property_readonly("linear_proxies", [](PyDeformer& s) { return s.lock(), s.deformer.linear_proxies(); })
      .def_property_readonly("patch_count", [](PyDeformer& s) { return s.lock(), s.deformer.patch_count(); })
      .def_property_readonly("handle_rows", [](PyDeformer& s) { return s.lock(), s.deformer.handle_rows(); })
      .def_property_readonly(
          "model", [](PyDeformer& s) { return s.lock(), s.model; }, "A copy of the Model.")
      .def_property_readonly(
          "options", [](PyDeformer& s) { return s.lock(), s.options; }, "A copy of the options.")
      .def_property_readonly(
          "handles", [](PyDeformer& s) { return s.lock(), s.handles; }, "The current Handles.");
}

// The state after precompute and the last frame, and handle_residual.
void bind_deformer_state(py::class_<PyDeformer>& cls) {
  cls
      .def_property_readonly(
          "model_name",
          [](PyDeformer& s) {
            const auto lock = s.lock();
            return s.deformer.model() ? s.deformer.model()->name() : std::string();
          },
          "'arap', 'conformal', or '' before precompute.")
      .def_property_readonly(
          "clusters", [](PyDeformer& s) { return s.lock(), s.deformer.clusters(); }, "Cluster per rotation element.")
      .def_property_readonly(
          "rotations", [](PyDeformer& s) { return s.lock(), Eigen::VectorXd(s.deformer.rotations()); },
          "S (9d): the cluster transforms, column-major 3×3 each (world frame).")
      .def_property_readonly(
          "cluster_scales", [](PyDeformer& s) { return s.lock(), s.deformer.cluster_scales(); },
          "ψ per cluster (1 for rotations; the conformal scale).")
      .def_property_readonly(
          "global_rotation", [](PyDeformer& s) { return s.lock(), Eigen::Matrix3d(s.deformer.global_rotation()); },
          "r₀ (3, 3).")
      .def(
          "patch_transform",
          [](PyDeformer& s, Index p) {
            const auto lock = s.lock();
            if (p < 0 || p >= s.deformer.patch_count()) {
              throw py::value_error("p: expected a patch index in [0, " + std::to_string(s.deformer.patch_count()) +
                                    "), got " + std::to_string(p));
            }
            return s.deformer.patch_transform(p);
          },
          py::arg("p"), "patch_transform(p) -> (3, 4) [t_s | d_s] of patch p after the last frame.")
      .def_property_readonly(
          "reconstruction_basis",
          [](PyDeformer& s) -> py::object {
            const auto lock = s.lock();
            const auto copy = [](const auto& basis) {  // 3n·p floats or doubles
              typename std::decay_t<decltype(basis)>::PlainObject B;
              {
                py::gil_scoped_release release;
                B = basis;
              }
              return py::cast(std::move(B));
            };
            return s.deformer.double_basis() ? copy(s.deformer.reconstruction_basis_double())
                                             : copy(s.deformer.reconstruction_basis());
          },
          "A copy of B = P·[N UD] (3n, p) in the normalised frame, float32 (float64 with "
          "DeformerOptions.double_basis): V′ = c + σ·r₀·(B·w) with (c, σ) = normalization (for a GPU "
          "reconstruction).")
      .def_property_readonly(
          "normalization",
          [](PyDeformer& s) {
            const auto lock = s.lock();
            const auto& f = s.deformer.normalization();
            return py::make_tuple(Eigen::Vector3d(f.centre), f.scale);
          },
          "(centre (3,) float64, scale): the deformer computes on (V − centre)/scale, scale the rest pose's "
          "bounding-box diagonal, so that no result depends on the mesh's units.")
      .def_property_readonly(
          "reduced_coordinates",
          [](PyDeformer& s) -> py::object {
            const auto lock = s.lock();
            if (s.deformer.double_basis()) return py::cast(Eigen::VectorXd(s.deformer.reduced_coordinates_double()));
            return py::cast(Eigen::VectorXf(s.deformer.reduced_coordinates()));
          },
          "w (p) of the last frame, float32 (float64 with DeformerOptions.double_basis).")
      .def(
          "handle_residual",
          [](PyDeformer& s, py::handle deformed) {
            const auto lock = s.lock();
            const auto Vp = matrix_view<double>("deformed", deformed, {s.model.V.rows(), "n"}, {3, "3"}, false);
            const Vertices copy = Vp;
            py::gil_scoped_release release;
            return handle_residual(s.model, s.handles, s.targets, copy);
          },
          py::arg("deformed"),
          "handle_residual(deformed) -> float: largest distance of a handle from the last frame's target.")
      .def("__repr__", [](PyDeformer& s) {
        const auto lock = s.lock();
        return "Deformer(n=" + std::to_string(s.model.V.rows()) + ", ready=" + (s.deformer.ready() ? "True" : "False") +
               ")";
      });
}

void bind_deformer_class(py::module_& m) {
  py::class_<PyDeformer> cls(
      m, "Deformer",
      "The reduced ARAP deformer (deformer.h): precompute once, set_handles per handle set (the\n"
      "on-site step), then frame per pose. Frames write V′ (n, 3) float64, into out= without a copy.\n\n"
      "Errors: a bad argument raises TypeError/ValueError naming it and the expected shape; a failed\n"
      "numerical step raises qpreduce.NumericalError (.status, .message, .summary).\n"
      "Threads: every call takes the deformer's own lock and the long ones (precompute, load, save,\n"
      "set_handles, frame) release the GIL, so different deformers run concurrently; one deformer may\n"
      "be shared, its calls then run one at a time.");
  bind_deformer_setup(cls);
  bind_deformer_precompute(cls);
  bind_deformer_onsite(cls);
  bind_deformer_rounds(cls);
  bind_deformer_state(cls);
}

}  // namespace

void bind_deformer(py::module_& deform) {
  bind_deformer_options(deform);  // bind_deform_options.cpp
  bind_handles(deform);  // bind_handles.cpp
  bind_model(deform);
  bind_deformer_class(deform);
}

}  // namespace qpreduce::python
