// qpreduce.deform.arap and qpreduce.deform.ArapSolver: ARAP in libigl's terms
// (deform/arap/arap.h). V (n, 3), F (m, 3) triangles or (m, 4) tets, b (h,)
// held vertices (any integer dtype), bc (h, 3) their targets.
#include "arguments.h"
#include "bindings.h"
#include "fields.h"
#include "locking.h"

#include <qpreduce/deform/arap/arap.h>

#include <pybind11/stl.h>

#include <mutex>

namespace qpreduce::python {

namespace {

using namespace qpreduce::deform;
using Elements = Eigen::Matrix<int, Eigen::Dynamic, Eigen::Dynamic, Eigen::RowMajor>;

struct MeshArgs {
  Vertices V;
  Elements F;
  std::vector<Index> b;
};

MeshArgs mesh_args(py::handle V, py::handle F, py::handle b) {
  const auto convert = py::module_::import("qpreduce._convert");
  MeshArgs a;
  a.V = convert.attr("as_rows")("V", V, py::make_tuple(3), "n", "float64").cast<Vertices>();
  a.F = convert.attr("as_rows")("F", F, py::make_tuple(3, 4), "m", "int32").cast<Elements>();
  const auto labels = convert.attr("as_labels")("b", b, -1, "h").cast<std::vector<int>>();
  a.b.assign(labels.begin(), labels.end());
  return a;
}

Vertices targets_arg(py::handle bc, Index h) { return dense_arg<double>("bc", bc, {h, "h"}, {3, "3"}); }

struct PyArapSolver {
  ArapSolver solver;
  bool strict = false;
  PrecomputeSummary precomputed;
  FrameSummary last_solve;
  py::object last_refine = py::none();
  std::mutex mutex;
  std::unique_lock<std::mutex> lock() { return lock_releasing_gil<std::unique_lock<std::mutex>>(mutex); }
};

void bind_arap_options(py::module_& m) {
  py::class_<ArapSolverOptions> options(m, "ArapSolverOptions",
                                        "Options of ArapSolver (arap.h); keyword construction.");
  Fields(options, "ArapSolverOptions")
      .rw("deformer", &ArapSolverOptions::deformer,
          "DeformerOptions of the reduced deformer; linear_proxies counts the samples beyond b.")
      .rw("max_rounds", &ArapSolverOptions::max_rounds, "Round cap of each solve (≥ 1). Default 500.")
      .rw("tolerance", &ArapSolverOptions::tolerance,
          "Each solve runs until the relative fixed-point residual is at most this. Default 1e-6.")
      .rw("refine", &ArapSolverOptions::refine, "RefineOptions of solve(..., refine=True).")
      .rw("max_basis_gb", &ArapSolverOptions::max_basis_gb,
          "Refuse the precompute (NumericalError, status NotRun) when the null-space block N (3n × 3(h + samples)\n"
          "doubles) would exceed this many GB; 0: no limit. Default 4.")
      .repr()
      .keyword_init<ArapSolverOptions>();
}

// solve(bc, out=None, *, refine=False).
void bind_arap_solve(py::class_<PyArapSolver>& cls) {
  cls
      .def(
          "solve",
          [](PyArapSolver& self, py::handle bc, py::handle out, bool refine) {
            const auto lock = self.lock();
            const Index n = self.solver.vertex_count();
            const Index h = static_cast<Index>(self.solver.handle_vertices().size());
            const Vertices targets = targets_arg(bc, h);
            py::array_t<double> result = out.is_none() ? py::array_t<double>(std::vector<py::ssize_t>{n, 3})
                                                       : py::reinterpret_borrow<py::array_t<double>>(out);
            auto view = matrix_view<double>("out", result, {n, "n"}, {3, "3"}, true);
            RefineSummary finish;
            {
              py::gil_scoped_release release;
              if (refine) {
                Vertices U;
                finish = self.solver.refine(targets, &U);
                if (U.rows() == n) view = U;
              } else {  // straight into the array
                self.last_solve = self.solver.solve(targets, Eigen::Map<Vertices>(view.data(), n, 3));
              }
            }
            if (refine) {
              self.last_refine = py::cast(finish);
              raise_if_unusable(finish, self.last_refine);
              if (!finish.converged) {
                warn_or_raise("ArapSolver.solve(refine=True): the full-space finish stopped after " +
                                  std::to_string(finish.rounds) +
                                  " rounds without converging (RefineOptions.max_iterations): " + finish.message,
                              self.strict, finish, self.last_refine);
              }
            } else {
              raise_if_unusable(self.last_solve, py::cast(self.last_solve));
            }
            return result;
          },
          py::arg("bc"), py::arg("out") = py::none(), py::kw_only(), py::arg("refine") = false,
          "solve(bc, out=None, *, refine=False) -> U (n, 3)\n\n"
          "bc (h, 3) float64: the targets of b, row i for b[i]. The reduced shape (a frame warm-started\n"
          "from the last solve, run to the tolerance), its rows b equal to bc; refine=True finishes it\n"
          "to converged classic ARAP (full space). out: C-contiguous (n, 3) float64 written in place.\n"
          "Summaries in .last_solve / .last_refine. Releases the GIL.");
}

// The summaries and sizes.
void bind_arap_solver_state(py::class_<PyArapSolver>& cls) {
  cls
      .def_property_readonly(
          "precompute_summary", [](PyArapSolver& s) { return s.lock(), s.precomputed; }, "PrecomputeSummary.")
      .def_property_readonly(
          "handle_summary", [](PyArapSolver& s) { return s.lock(), s.solver.handle_summary(); },
          "ConstraintSummary of the handle set (Success: met exactly).")
      .def_property_readonly(
          "last_solve", [](PyArapSolver& s) { return s.lock(), s.last_solve; }, "FrameSummary of the last solve.")
      .def_property_readonly(
          "last_refine", [](PyArapSolver& s) { return s.lock(), s.last_refine; },
          "RefineSummary of the last solve(refine=True), or None.")
      .def_property_readonly(
          "reconstruction_handle_error",
          [](PyArapSolver& s) { return s.lock(), s.solver.reconstruction_handle_error(); },
          "How far the last solve's float reconstruction put b from bc before those rows were written.")
      .def_property_readonly(
          "handle_vertices", [](PyArapSolver& s) { return s.lock(), s.solver.handle_vertices(); }, "b, as given.")
      .def_property_readonly(
          "vertex_count", [](PyArapSolver& s) { return s.lock(), s.solver.vertex_count(); }, "n.");
}

void bind_arap_solver(py::module_& m) {
  py::class_<PyArapSolver> cls(
      m, "ArapSolver",
      "Repeated ARAP solves with the same held vertices b, in libigl's terms (arap.h): every vertex of\n"
      "b is its own linear proxy of the reduced deformer, so any targets bc are met exactly; solve(bc)\n"
      "is a reduced solve to its fixed point (milliseconds), solve(bc, refine=True) finishes it to\n"
      "converged classic ARAP in the full space. For a single solve, deform.arap is cheaper.");
  cls.def(py::init([](py::handle V, py::handle F, py::handle b, py::handle options, bool strict) {
             MeshArgs a = mesh_args(V, F, b);
             const auto opts = options_arg<ArapSolverOptions>("options", options);
             auto self = std::make_unique<PyArapSolver>();
             self->strict = strict;
             {
               py::gil_scoped_release release;
               self->precomputed = self->solver.precompute(a.V, a.F, a.b, opts);
             }
             raise_if_unusable(self->precomputed, py::cast(self->precomputed));
             const ConstraintSummary& hs = self->solver.handle_summary();
             if (!hs.ok()) {
               warn_or_raise("ArapSolver: the handles are met only in the least-squares sense: " + hs.message, strict,
                             hs, py::cast(hs));
             }
             return self;
           }),
           py::arg("V"), py::arg("F"), py::arg("b"), py::kw_only(), py::arg("options") = py::none(),
           py::arg("strict") = false,
           "ArapSolver(V, F, b, *, options=None, strict=False)\n\n"
           "V (n, 3) float64; F (m, 3) triangles or (m, 4) tetrahedra, integers; b (h,) held vertex\n"
           "indices, any integer dtype, distinct; options: ArapSolverOptions. Precomputes the reduced\n"
           "deformer (seconds; cost grows with h, docs/performance.md). ValueError/TypeError naming a bad\n"
           "argument; NumericalError when the precompute fails. Releases the GIL.");
  bind_arap_solve(cls);
  bind_arap_solver_state(cls);
}

}  // namespace

void bind_arap(py::module_& deform) {
  bind_arap_options(deform);
  bind_arap_solver(deform);
  deform.def(
      "arap",
      [](py::handle V, py::handle F, py::handle b, py::handle bc, py::handle U, py::handle options, bool return_summary,
         bool strict) {
        MeshArgs a = mesh_args(V, F, b);
        const Vertices targets = targets_arg(bc, static_cast<Index>(a.b.size()));
        const auto opts = options_arg<RefineOptions>("options", options);
        const Index n = a.V.rows();
        py::array_t<double> result = U.is_none() ? py::array_t<double>(std::vector<py::ssize_t>{n, 3})
                                                 : py::reinterpret_borrow<py::array_t<double>>(U);
        auto view = matrix_view<double>("U", result, {n, "n"}, {3, "3"}, true);
        Vertices pose;
        if (!U.is_none()) pose = view;  // libigl's arap_solve reads U as the initial guess
        RefineSummary summary;
        {
          py::gil_scoped_release release;
          summary = arap(a.V, a.F, a.b, targets, &pose, opts);
          if (pose.rows() == n) view = pose;
        }
        const py::object summary_object = py::cast(summary);
        raise_if_unusable(summary, summary_object);
        if (!summary.converged) {
          warn_or_raise("arap: stopped after " + std::to_string(summary.rounds) +
                            " rounds without converging (RefineOptions.max_iterations): " + summary.message,
                        strict, summary, summary_object);
        }
        if (return_summary) return py::object(py::make_tuple(result, summary_object));
        return py::object(result);
      },
      py::arg("V"), py::arg("F"), py::arg("b"), py::arg("bc"), py::arg("U") = py::none(), py::kw_only(),
      py::arg("options") = py::none(), py::arg("return_summary") = false, py::arg("strict") = false,
      "arap(V, F, b, bc, U=None, *, options=None, return_summary=False, strict=False) -> U (n, 3)\n\n"
      "One converged classic ARAP solve in the full space (arap.h), as igl.arap_precomputation then\n"
      "igl.arap_solve: V (n, 3) float64; F (m, 3) triangles or (m, 4) tetrahedra; b (h,) held vertices\n"
      "(any integer dtype, distinct); bc (h, 3) their targets; U (n, 3) C-contiguous float64, read as\n"
      "the initial guess and overwritten (None: start from V, a new array). options: RefineOptions.\n"
      "return_summary=True returns (U, RefineSummary). A solve that stops at the round limit warns\n"
      "(QpreduceWarning; NumericalError under strict). Releases the GIL.");
}

}  // namespace qpreduce::python
