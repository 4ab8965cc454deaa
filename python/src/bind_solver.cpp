// SubspaceSolver (subspace_solver.h) for float64 and float32. Each Python
// object holds the solver and a reader–writer lock: precompute, restore and
// set_constraints* take it exclusively (with the GIL released), the const
// calls share it, so one solver may be used from several threads without a
// data race; different solvers never wait for each other.
#include "arguments.h"
#include "bindings.h"
#include "locking.h"

#include <qpreduce/subspace_solver.h>

#include <mutex>
#include <shared_mutex>

namespace qpreduce::python {

namespace {

template <typename Scalar>
struct LockedSolver {
  SubspaceSolver<Scalar> solver;
  mutable std::shared_mutex mutex;

  // A shared lock for the const calls (no GIL round trip unless a writer holds it).
  std::shared_lock<std::shared_mutex> read() const {
    return lock_releasing_gil<std::shared_lock<std::shared_mutex>>(mutex);
  }
  void require_constrained(const char* what) const {
    if (!solver.constrained()) {
      throw py::value_error(std::string(what) + ": call precompute and set_constraints first");
    }
  }
};

template <typename Scalar>
py::object float_name() {
  return py::dtype::of<Scalar>().attr("name");
}

// A dimension of the solver: which size (n, p, k) and its name in the docs.
template <typename Scalar>
struct SolverDim {
  Index (SubspaceSolver<Scalar>::*size)() const;
  const char* label;
};

// y = map(x) for one of the solver's linear maps (reconstruct, reduce_linear_term*):
// x read in place, y written into `out` or a new array, the GIL released.
template <typename Scalar>
py::array_t<Scalar> apply_map(const LockedSolver<Scalar>& self,
                              void (SubspaceSolver<Scalar>::*map)(const Eigen::Ref<const Vector<Scalar>>&,
                                                                  Eigen::Ref<Vector<Scalar>>) const,
                              const char* x_name, py::handle x, SolverDim<Scalar> x_dim, py::handle out,
                              SolverDim<Scalar> y_dim) {
  const auto lock = self.read();
  const auto xv = vector_arg<Scalar>(x_name, x, {(self.solver.*x_dim.size)(), x_dim.label});
  const Index ny = (self.solver.*y_dim.size)();
  auto y = output_arg<Scalar>("out", out, {ny, y_dim.label}, {{x_name, xv}});
  Eigen::Map<Vector<Scalar>> yv(y.mutable_data(), ny);
  py::gil_scoped_release release;
  (self.solver.*map)(xv, yv);
  return y;
}

// The subspace type of a solver (its N and UD).
template <typename Scalar>
void bind_subspace_type(py::module_& m, const char* name) {
  py::class_<VariationalSubspace<Scalar>>(m, (std::string(name) + "Subspace").c_str(),
                                          "The subspace X = N·z + UD·y (subspace.h): N n×d, UD n×k.")
      .def_readonly("N", &VariationalSubspace<Scalar>::N, "n × d")
      .def_readonly("UD", &VariationalSubspace<Scalar>::UD, "n × k")
      .def("__repr__", [name](const VariationalSubspace<Scalar>& s) {
        return std::string(name) + "Subspace(N: " + std::to_string(s.N.rows()) + "×" + std::to_string(s.N.cols()) +
               ", UD: " + std::to_string(s.UD.rows()) + "×" + std::to_string(s.UD.cols()) + ")";
      });
}

// precompute, restore and the constraints.
template <typename Scalar>
void bind_solver_setup(py::class_<LockedSolver<Scalar>>& cls) {
  using Locked = LockedSolver<Scalar>;
  using MatrixS = Matrix<Scalar>;
  cls
      .def(py::init<>(), "An empty solver (ready is False).")
      .def(
          "precompute",
          [](Locked& self, py::handle H, py::handle C, py::handle D, py::handle options) {
            const auto design = design_args<Scalar>(H, C, D);
            const auto opts = options_arg<SubspaceOptions>("options", options);
            py::gil_scoped_release release;
            std::unique_lock<std::shared_mutex> lock(self.mutex);
            return self.solver.precompute(design.H, design.C, design.D, opts);
          },
          py::arg("H"), py::arg("C"), py::arg("D") = py::none(), py::arg("options") = py::none(),
          "precompute(H, C, D=None, options=None) -> SubspaceSummary\n\n"
          "Builds the subspace from one factorization and H_r = BᵀHB, BᵀD.\n"
          "H: n×n symmetric PSD; C: n×d (d ≥ 1); D: n×k, None for k = 0. Each a scipy.sparse matrix\n"
          "(any format and index dtype) or a dense array, copied. Raises ValueError on bad sizes,\n"
          "NaN/Inf, an asymmetric H, d = 0 or invalid options; numerical failures come back in the\n"
          "summary and leave the solver unusable (ready False). Releases the GIL.")
      .def(
          "restore",
          [](Locked& self, py::handle N, py::handle UD, py::handle Hr, py::handle BtD, py::handle options) {
            VariationalSubspace<Scalar> subspace;
            subspace.N = dense_arg<Scalar>("N", N, {-1, "n"}, {-1, "d"});
            subspace.UD = dense_arg<Scalar>("UD", UD, {subspace.N.rows(), "n"}, {-1, "k"});
            const Index p = subspace.N.cols() + subspace.UD.cols();
            auto Hr_d = dense_arg<double>("Hr", Hr, {p, "p"}, {p, "p"});
            auto BtD_d = dense_arg<double>("BtD", BtD, {p, "p"}, {subspace.UD.cols(), "k"});
            const auto opts = options_arg<SubspaceOptions>("options", options);
            py::gil_scoped_release release;
            std::unique_lock<std::shared_mutex> lock(self.mutex);
            self.solver.restore(std::move(subspace), std::move(Hr_d), std::move(BtD_d), opts);
          },
          py::arg("N"), py::arg("UD"), py::arg("Hr"), py::arg("BtD"), py::arg("options") = py::none(),
          "restore(N, UD, Hr, BtD, options=None)\n\n"
          "Restores a precomputed solver from its parts: N n×d, UD n×k, Hr = BᵀHB p×p (symmetric),\n"
          "BtD = BᵀD p×k, as precompute made them with the same options (e.g. solver.subspace.N,\n"
          "solver.reduced_hessian, solver.reduced_linear_map). Redoes the O(p³) fast-path preparation.\n"
          "Raises ValueError on inconsistent sizes, NaN/Inf or an asymmetric Hr.")
      .def(
          "set_constraints",
          [](Locked& self, py::handle A, py::handle options) {
            auto As = sparse_arg<Scalar>("A", A, {self.solver.n(), "n"}, {-1, "m"});
            const auto opts = options_arg<ConstraintOptions>("options", options);
            py::gil_scoped_release release;
            std::unique_lock<std::shared_mutex> lock(self.mutex);
            return self.solver.set_constraints(As, opts);
          },
          py::arg("A"), py::arg("options") = py::none(),
          "set_constraints(A, options=None) -> ConstraintSummary\n\n"
          "The on-site step for constraints AᵀX = b, A n×m (m may be 0; scipy.sparse or dense).\n"
          "ConstraintOptions(soft=True, delta=...) gives soft constraints (Eq. 18). Raises ValueError\n"
          "on a wrong row count, NaN, or before a successful precompute. Releases the GIL.")
      .def(
          "set_constraints_in_design",
          [](Locked& self, py::handle A_c, py::handle options) {
            MatrixS Ac = dense_arg<Scalar>("A_c", A_c, {self.solver.d(), "d"}, {-1, "m"});
            const auto opts = options_arg<ConstraintOptions>("options", options);
            py::gil_scoped_release release;
            std::unique_lock<std::shared_mutex> lock(self.mutex);
            return self.solver.set_constraints_in_design(Ac, opts);
          },
          py::arg("A_c"), py::arg("options") = py::none(),
          "set_constraints_in_design(A_c, options=None) -> ConstraintSummary\n\n"
          "Constraints given in the design space, A = C·A_c (A_c d×m): A_r = [A_cᵀ 0], no term in n.\n"
          "Raises ValueError when A_c does not have d rows, holds NaN, or before precompute.");
}

// The solves and the reductions.
template <typename Scalar>
void bind_solver_solves(py::class_<LockedSolver<Scalar>>& cls) {
  using Locked = LockedSolver<Scalar>;
  using Solver = SubspaceSolver<Scalar>;
  cls
      .def(
          "solve",
          [](const Locked& self, py::handle b, py::handle q_r, py::handle out) {
            const auto lock = self.read();
            self.require_constrained("SubspaceSolver.solve");
            const Index m = self.solver.m(), p = self.solver.p();
            const auto bv = vector_arg<Scalar>("b", b, {m, "m"});
            const auto qv = vector_arg<Scalar>("q_r", q_r, {p, "p"});
            auto w = output_arg<Scalar>("out", out, {p, "p"}, {{"b", bv}, {"q_r", qv}});
            Eigen::Map<Vector<Scalar>> wv(w.mutable_data(), p);
            self.solver.solve(bv, qv, wv);
            return w;
          },
          py::arg("b"), py::arg("q_r"), py::arg("out") = py::none(),
          "solve(b, q_r, out=None) -> w\n\n"
          "w = M_b·b + M_q·q_r (p). b: (m,), q_r: (p,) (see reduce_linear_term), out: (p,) or None;\n"
          "contiguous numpy arrays of the solver's dtype, used in place (no copy).")
      .def(
          "solve_in_D",
          [](const Locked& self, py::handle b, py::handle Y, py::handle out) {
            const auto lock = self.read();
            self.require_constrained("SubspaceSolver.solve_in_D");
            const Index m = self.solver.m(), k = self.solver.k(), p = self.solver.p();
            const auto bv = vector_arg<Scalar>("b", b, {m, "m"});
            const auto Yv = vector_arg<Scalar>("Y", Y, {k, "k"});
            auto w = output_arg<Scalar>("out", out, {p, "p"}, {{"b", bv}, {"Y", Yv}});
            Eigen::Map<Vector<Scalar>> wv(w.mutable_data(), p);
            self.solver.solve_in_D(bv, Yv, wv);
            return w;
          },
          py::arg("b"), py::arg("Y"), py::arg("out") = py::none(),
          "solve_in_D(b, Y, out=None) -> w\n\n"
          "The same with q = D·Y: w = M_b·b + M_Y·Y (p). b: (m,), Y: (k,), out: (p,) or None;\n"
          "contiguous numpy arrays of the solver's dtype, used in place (no copy).")
      .def(
          "reconstruct",
          [](const Locked& self, py::handle w, py::handle out) {
            return apply_map<Scalar>(self, &Solver::reconstruct, "w", w, {&Solver::p, "p"}, out, {&Solver::n, "n"});
          },
          py::arg("w"), py::arg("out") = py::none(),
          "reconstruct(w, out=None) -> X\n\nX = N·z + UD·y (n) for w = [z; y] (p). Cost O(n·p); releases the GIL.")
      .def(
          "reduce_linear_term",
          [](const Locked& self, py::handle q, py::handle out) {
            return apply_map<Scalar>(self, &Solver::reduce_linear_term, "q", q, {&Solver::n, "n"}, out,
                                     {&Solver::p, "p"});
          },
          py::arg("q"), py::arg("out") = py::none(),
          "reduce_linear_term(q, out=None) -> q_r\n\nq_r = Bᵀq (p) for a general linear term q (n). Cost O(n·p).")
      .def(
          "reduce_linear_term_in_D",
          [](const Locked& self, py::handle Y, py::handle out) {
            return apply_map<Scalar>(self, &Solver::reduce_linear_term_in_D, "Y", Y, {&Solver::k, "k"}, out,
                                     {&Solver::p, "p"});
          },
          py::arg("Y"), py::arg("out") = py::none(),
          "reduce_linear_term_in_D(Y, out=None) -> q_r\n\nq_r = BᵀD·Y (p) for q = D·Y (Y: k). Cost O(p·k).");
}

// Sizes, state and copies of the reduced operators.
template <typename Scalar>
void bind_solver_state(py::class_<LockedSolver<Scalar>>& cls, const char* name) {
  using Locked = LockedSolver<Scalar>;
  using MatrixS = Matrix<Scalar>;
  cls
      .def_property_readonly("n", [](const Locked& s) { return s.read(), s.solver.n(); }, "Unknowns.")
      .def_property_readonly("d", [](const Locked& s) { return s.read(), s.solver.d(); }, "Columns of C (N).")
      .def_property_readonly("k", [](const Locked& s) { return s.read(), s.solver.k(); }, "Columns of D (UD).")
      .def_property_readonly("p", [](const Locked& s) { return s.read(), s.solver.p(); }, "p = d + k.")
      .def_property_readonly("m", [](const Locked& s) { return s.read(), s.solver.m(); }, "Current constraints.")
      .def_property_readonly("ready", [](const Locked& s) { return s.read(), s.solver.ready(); },
                             "A precompute or restore succeeded.")
      .def_property_readonly("constrained", [](const Locked& s) { return s.read(), s.solver.constrained(); },
                             "set_constraints succeeded: solve may be called.")
      .def_property_readonly(
          "subspace", [](const Locked& s) { return s.read(), s.solver.subspace(); },
          "A copy of the subspace: .N (n×d), .UD (n×k).")
      .def_property_readonly(
          "reduced_hessian", [](const Locked& s) { return s.read(), MatrixS(s.solver.reduced_hessian()); },
          "A copy of H_r = BᵀHB (p×p).")
      .def_property_readonly(
          "reduced_constraints", [](const Locked& s) { return s.read(), MatrixS(s.solver.reduced_constraints()); },
          "A copy of A_r = AᵀB (m×p).")
      .def_property_readonly(
          "reduced_linear_map", [](const Locked& s) { return s.read(), MatrixS(s.solver.reduced_linear_map()); },
          "A copy of BᵀD (p×k): q_r = BᵀD·Y.")
      .def("__repr__", [name](const Locked& s) {
        const auto lock = s.read();
        return std::string(name) + "(n=" + std::to_string(s.solver.n()) + ", d=" + std::to_string(s.solver.d()) +
               ", k=" + std::to_string(s.solver.k()) + ", m=" + std::to_string(s.solver.m()) +
               ", ready=" + (s.solver.ready() ? "True" : "False") + ")";
      });
}

template <typename Scalar>
void bind_solver_type(py::module_& m, const char* name) {
  const std::string dtype = float_name<Scalar>().template cast<std::string>();
  bind_subspace_type<Scalar>(m, name);
  const std::string doc =
      "The reduced solver (subspace_solver.h), " + dtype + ": precompute once, then any demand (A, b, q).\n\n"
      "Eq. 1  min_X ½XᵀHX − qᵀX  s.t.  AᵀX = b  (H n×n PSD, A n×m) becomes, with X = B·w,\n"
      "B = [N UD] (n×p, p = d + k, w = [z; y]),  min_w ½wᵀH_r w − q_rᵀw  s.t.  A_r w = b,\n"
      "H_r = BᵀHB (p×p), A_r = AᵀB (m×p), q_r = Bᵀq (p). set_constraints forms the small\n"
      "operators; solve is a few matrix–vector products. Bad arguments raise ValueError or\n"
      "TypeError; numerical failures come back as summaries (summary.raise_if_failed()).\n"
      "Thread safety: calls on one solver are serialised by a reader–writer lock (the\n"
      "const calls run concurrently); the GIL is released in the long calls.";
  py::class_<LockedSolver<Scalar>> cls(m, name, doc.c_str());
  bind_solver_setup<Scalar>(cls);
  bind_solver_solves<Scalar>(cls);
  bind_solver_state<Scalar>(cls, name);
}

}  // namespace

void bind_solver(py::module_& m) {
  bind_solver_type<double>(m, "SubspaceSolver");
  bind_solver_type<float>(m, "SubspaceSolver32");
}

}  // namespace qpreduce::python
