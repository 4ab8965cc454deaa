// The full-space reference solve (full_solve.h), the quotient analysis
// (quotient.h) and the Theorem 4.10 checker (theorem.h). Each call copies its
// inputs and releases the GIL; the results are plain objects.
#include "arguments.h"
#include "bindings.h"
#include "fields.h"
#include "locking.h"

#include <qpreduce/full_solve.h>
#include <qpreduce/quotient.h>
#include <qpreduce/theorem.h>

#include <pybind11/stl.h>

#include <mutex>
#include <optional>

namespace qpreduce::python {

namespace {

// A demand (A n×m, b m, q n) for a problem of n unknowns.
struct Demand {
  SparseMatrix<double> A;
  Vector<double> b, q;
};
Demand demand_args(Index n, py::handle A, py::handle b, py::handle q) {
  Demand demand;
  demand.A = sparse_arg<double>("A", A, {n, "n"}, {-1, "m"});
  demand.b = vector_copy_arg<double>("b", b, {demand.A.cols(), "m"});
  demand.q = vector_copy_arg<double>("q", q, {n, "n"});
  return demand;
}

void bind_full_solve(py::module_& m) {
  m.def(
      "solve_full",
      [](py::handle H, py::handle A, py::handle b, py::handle q, py::handle options) {
        const auto Hs = square_sparse_arg<double>("H", H);
        const Demand demand = demand_args(Hs.rows(), A, b, q);
        const auto opts = options_arg<SubspaceOptions>("options", options);
        Vector<double> X;
        FullSolveSummary summary;
        {
          py::gil_scoped_release release;
          summary = solve_full(Hs, demand.A, demand.b, demand.q, &X, opts);
        }
        return py::make_tuple(X.size() ? py::cast(X) : py::none(), summary);
      },
      py::arg("H"), py::arg("A"), py::arg("b"), py::arg("q"), py::arg("options") = py::none(),
      "solve_full(H, A, b, q, options=None) -> (X, FullSolveSummary)\n\n"
      "Full-space reference solve of Eq. 1: min ½XᵀHX − qᵀX s.t. AᵀX = b. H: n×n PSD, A: n×m\n"
      "(full column rank, H PD on ker Aᵀ), both scipy.sparse or dense; b: (m,), q: (n,).\n"
      "X: (n,) or None when the summary reports a failure. Releases the GIL.");
}

// The PSD factor of H, and the H-distance.
void bind_quotient(py::module_& m) {
  py::class_<PsdFactor>(m, "PsdFactor", "H = LᵀL, rank-revealing (quotient.h).")
      .def_readonly("L", &PsdFactor::L, "r × n")
      .def_readonly("L_pinv", &PsdFactor::L_pinv, "n × r")
      .def_readonly("kernel", &PsdFactor::kernel, "n × ν, orthonormal basis of ker H")
      .def_readonly("eigenvalues", &PsdFactor::eigenvalues, "(n,), ascending")
      .def_property_readonly("n", &PsdFactor::n)
      .def_property_readonly("rank", &PsdFactor::rank)
      .def_property_readonly("nullity", &PsdFactor::nullity)
      .def(
          "whiten",
          [](const PsdFactor& f, py::handle M) { return f.whiten(dense_arg<double>("M", M, {f.n(), "n"}, {-1, "c"})); },
          py::arg("M"), "whiten(M) -> (L⁺)ᵀ·M, r × c, for M n × c.")
      .def(
          "null_part",
          [](const PsdFactor& f, py::handle X) { return f.null_part(vector_copy_arg<double>("X", X, {f.n(), "n"})); },
          py::arg("X"), "null_part(X) -> K·KᵀX (n,), the component of X (n,) in ker H.")
      .def(
          "distance",
          [](const PsdFactor& f, py::handle x, py::handle y) {
            return f.distance(vector_copy_arg<double>("x", x, {f.n(), "n"}),
                              vector_copy_arg<double>("y", y, {f.n(), "n"}));
          },
          py::arg("x"), py::arg("y"), "distance(x, y) -> d_H(x, y) = ‖L(x − y)‖, x, y: (n,).");

  m.def(
      "factor_psd",
      [](py::handle H, py::handle options) {
        const auto Hs = square_sparse_arg<double>("H", H);
        const auto opts = options_arg<QuotientOptions>("options", options);
        PsdFactor factor;
        FactorSummary summary;
        {
          py::gil_scoped_release release;
          summary = factor_psd(Hs, opts, &factor);
        }
        return py::make_tuple(summary.ok() ? py::cast(factor) : py::none(), summary);
      },
      py::arg("H"), py::arg("options") = py::none(),
      "factor_psd(H, options=None) -> (PsdFactor or None, FactorSummary)\n\n"
      "Rank-revealing H = LᵀL of a symmetric PSD H (n×n, sparse or dense; dense eigensolver,\n"
      "a few hundred unknowns). An indefinite H gives Status.IndefiniteH and None.");
  m.def(
      "h_distance",
      [](py::handle H, py::handle x, py::handle y) {
        const auto Hs = square_sparse_arg<double>("H", H);
        return h_distance(Hs, vector_copy_arg<double>("x", x, {Hs.rows(), "n"}),
                          vector_copy_arg<double>("y", y, {Hs.rows(), "n"}));
      },
      py::arg("H"), py::arg("x"), py::arg("y"), "h_distance(H, x, y) -> sqrt(max(0, (x − y)ᵀH(x − y))).");
}

// The whitened design spaces and demands (Eq. 25–29).
void bind_whitening(py::module_& m) {
  py::class_<WhitenedDesign> design(m, "WhitenedDesign", "Whitened design spaces (quotient.h, Eq. 25–29).");
  Fields(design, "WhitenedDesign")
      .ro("C_hat", &WhitenedDesign::C_hat, "r × d, Ĉ = (L⁺)ᵀC")
      .ro("D_hat", &WhitenedDesign::D_hat, "r × k, D̂ = (L⁺)ᵀD")
      .ro("basis", &WhitenedDesign::basis, "r × s, orthonormal basis of Span(Ĉ) + Span(D̂)")
      .ro("I_hat", &WhitenedDesign::I_hat, "r × r, Î")
      .ro("U_hat", &WhitenedDesign::U_hat, "r × r, Û = I − ĈĈ⁺")
      .ro("N_hat", &WhitenedDesign::N_hat, "r × d")
      .ro("UD_hat", &WhitenedDesign::UD_hat, "r × k")
      .ro("rank_C_hat", &WhitenedDesign::rank_C_hat, "rank of Ĉ")
      .ro("rank", &WhitenedDesign::rank, "s = dim(Span(Ĉ) + Span(D̂))")
      .ro("kernel_angle", &WhitenedDesign::kernel_angle, "sine of the largest angle between ker H and the design");
  design.def("kernel_in_design", &WhitenedDesign::kernel_in_design, py::arg("tolerance") = 1e-8)
      .def("independent", &WhitenedDesign::independent);
  m.def(
      "whiten_design",
      [](const PsdFactor& factor, py::handle C, py::handle D, py::handle options) {
        auto Cd = dense_arg<double>("C", C, {factor.n(), "n"}, {-1, "d"});
        auto Dd = dense_arg<double>("D", D, {factor.n(), "n"}, {-1, "k"});
        const auto opts = options_arg<QuotientOptions>("options", options);
        py::gil_scoped_release release;
        return whiten_design(factor, Cd, Dd, opts);
      },
      py::arg("factor"), py::arg("C"), py::arg("D"), py::arg("options") = py::none(),
      "whiten_design(factor, C, D, options=None) -> WhitenedDesign; C: n×d, D: n×k.");

  py::class_<CompanionDemand> companion(m, "CompanionDemand", "Whitened demand (quotient.h).");
  Fields(companion, "CompanionDemand")
      .ro("A_hat", &CompanionDemand::A_hat, "r × m, Â = (L⁺)ᵀA")
      .ro("q_hat", &CompanionDemand::q_hat, "(r,), q̂ = (L⁺)ᵀq")
      .ro("b_hat", &CompanionDemand::b_hat, "(m,), b̂ = b − AᵀX̄_min")
      .ro("X_bar", &CompanionDemand::X_bar, "(n,), X̄_min = (I − L⁺L)·X_min");
  m.def(
      "companion_demand",
      [](const PsdFactor& factor, py::handle A, py::handle b, py::handle q, py::handle X_min) {
        const Index n = factor.n();
        auto Ad = dense_arg<double>("A", A, {n, "n"}, {-1, "m"});
        auto bv = vector_copy_arg<double>("b", b, {Ad.cols(), "m"});
        auto qv = vector_copy_arg<double>("q", q, {n, "n"});
        auto Xv = vector_copy_arg<double>("X_min", X_min, {n, "n"});
        py::gil_scoped_release release;
        return companion_demand(factor, Ad, bv, qv, Xv);
      },
      py::arg("factor"), py::arg("A"), py::arg("b"), py::arg("q"), py::arg("X_min"),
      "companion_demand(factor, A, b, q, X_min) -> CompanionDemand; A: n×m, b: (m,), q, X_min: (n,).");
  m.def(
      "companion_solution",
      [](const CompanionDemand& demand, py::handle options) -> std::optional<Vector<double>> {
        const auto opts = options_arg<QuotientOptions>("options", options);
        Vector<double> X;
        if (!companion_solution(demand, &X, opts)) return std::nullopt;
        return X;
      },
      py::arg("demand"), py::arg("options") = py::none(),
      "companion_solution(demand, options=None) -> X̂_min (r,) of Eq. 30, None when Â lacks full column rank.");
  m.def(
      "subspace_companion_solution",
      [](const WhitenedDesign& design, const CompanionDemand& demand,
         py::handle options) -> std::optional<Vector<double>> {
        const auto opts = options_arg<QuotientOptions>("options", options);
        Vector<double> X;
        if (!subspace_companion_solution(design, demand, &X, opts)) return std::nullopt;
        return X;
      },
      py::arg("design"), py::arg("demand"), py::arg("options") = py::none(),
      "subspace_companion_solution(design, demand, options=None) -> X̂*_min (r,) of Eq. 35, None when ÎÂ\n"
      "lacks full column rank.");
}

// TheoremChecker and a lock: check() sets constraints on the checker's solver.
struct LockedChecker {
  TheoremChecker checker;
  std::mutex mutex;

  std::unique_lock<std::mutex> lock() { return lock_releasing_gil<std::unique_lock<std::mutex>>(mutex); }
};

// The bound's terms and one demand's check (Eq. 39).
void bind_theorem(py::module_& m) {
  py::class_<TheoremBound> bound(m, "TheoremBound", "All terms of Eq. 39 for one demand (theorem.h).");
  Fields(bound, "TheoremBound")
      .ro("status", &TheoremBound::status, "TheoremStatus")
      .ro("message", &TheoremBound::message, "")
      .ro("r", &TheoremBound::r, "rank of H")
      .ro("m", &TheoremBound::m, "constraints")
      .ro("q_residual", &TheoremBound::q_residual, "‖Îq̂ − q̂‖")
      .ro("A_residual", &TheoremBound::A_residual, "δ = ‖ÎÂ − Â‖₂")
      .ro("rho", &TheoremBound::rho, "ρ = ‖I − Â⁺ÎÂ‖₂")
      .ro("omega", &TheoremBound::omega, "ω = cond(Â)")
      .ro("beta1", &TheoremBound::beta1, "(2 − ρ)/(1 − ρ)")
      .ro("beta2", &TheoremBound::beta2, "1 + ω/(1 − ρ)")
      .ro("Delta", &TheoremBound::Delta, "Δ = β₁‖b̂‖‖Â⁺‖² + β₂‖q̂‖‖Â⁺‖")
      .ro("norm_q_hat", &TheoremBound::norm_q_hat, "‖q̂‖")
      .ro("norm_b_hat", &TheoremBound::norm_b_hat, "‖b̂‖")
      .ro("norm_A_hat", &TheoremBound::norm_A_hat, "‖Â‖₂")
      .ro("norm_A_pinv", &TheoremBound::norm_A_pinv, "‖Â⁺‖₂")
      .ro("norm_Ap_pinv", &TheoremBound::norm_Ap_pinv, "‖Â_p⁺‖₂")
      .ro("bound", &TheoremBound::bound, "Eq. 39 (inf when the theorem does not apply)")
      .ro("refined_bound", &TheoremBound::refined_bound, "a-posteriori bound")
      .repr();
  bound.def("applies", &TheoremBound::applies);
  m.def(
      "theorem_bound",
      [](const WhitenedDesign& design, const CompanionDemand& demand, py::handle options) {
        const auto opts = options_arg<QuotientOptions>("options", options);
        py::gil_scoped_release release;
        return theorem_bound(design, demand, opts);
      },
      py::arg("design"), py::arg("demand"), py::arg("options") = py::none(),
      "theorem_bound(design, demand, options=None) -> TheoremBound (never NaN).");

  py::class_<TheoremCheck> check(m, "TheoremCheck", "One demand end to end (theorem.h).");
  Fields(check, "TheoremCheck")
      .ro("status", &TheoremCheck::status, "TheoremStatus")
      .ro("message", &TheoremCheck::message, "")
      .ro("exact_norm", &TheoremCheck::exact_norm, "‖X̂_min‖")
      .ro("exact_kkt_residual", &TheoremCheck::exact_kkt_residual, "dense KKT residual")
      .ro("practical_error", &TheoremCheck::practical_error, "d_H(X*, X_min)")
      .ro("practical_rel_error", &TheoremCheck::practical_rel_error, "‖X* − X_min‖/‖X_min‖")
      .ro("theorem_error", &TheoremCheck::theorem_error, "‖X̂*_min − X̂_min‖ (−1 if undefined)")
      .ro("practical_gap", &TheoremCheck::practical_gap, "‖L·X* − X̂*_min‖")
      .ro("closed_form_gap", &TheoremCheck::closed_form_gap, "‖X̂_min(Eq. 30) − L·X_min‖")
      .ro("practical_covered", &TheoremCheck::practical_covered, "ker H ⊆ Span(C) + Span(D)")
      .ro("slack", &TheoremCheck::slack, "round-off allowance")
      .ro("seconds", &TheoremCheck::seconds, "")
      .ro("bound", &TheoremCheck::bound, "TheoremBound")
      .repr();
  check.def("practical_violation", &TheoremCheck::practical_violation)
      .def("theorem_violation", &TheoremCheck::theorem_violation)
      .def("eta", &TheoremCheck::eta, "bound / practical_error (inf when the error is 0).");

  py::class_<TheoremSolutions> solutions(m, "TheoremSolutions", "Optional outputs of TheoremChecker.check.");
  Fields(solutions, "TheoremSolutions")
      .ro("X_min", &TheoremSolutions::X_min, "(n,), exact")
      .ro("X_star", &TheoremSolutions::X_star, "(n,), the engine's answer")
      .ro("X_hat_min", &TheoremSolutions::X_hat_min, "(r,), Eq. 30")
      .ro("X_hat_star", &TheoremSolutions::X_hat_star, "(r,), Eq. 35 (empty when undefined)")
      .ro("demand", &TheoremSolutions::demand, "CompanionDemand");
}

// TheoremChecker (precompute once, check many demands) and check_theorem.
void bind_theorem_checker(py::module_& m) {
  py::class_<LockedChecker>(m, "TheoremChecker",
                            "Precompute once per (H, C, D), then check many demands (theorem.h). Calls on one\n"
                            "checker are serialised by a lock (check() mutates the engine's constraints).")
      .def(py::init<>())
      .def(
          "precompute",
          [](LockedChecker& self, py::handle H, py::handle C, py::handle D, py::handle options) {
            const auto design = design_args<double>(H, C, D);
            const auto opts = options_arg<QuotientOptions>("options", options);
            py::gil_scoped_release release;
            std::lock_guard<std::mutex> lock(self.mutex);
            return self.checker.precompute(design.H, design.C, design.D, opts);
          },
          py::arg("H"), py::arg("C"), py::arg("D") = py::none(), py::arg("options") = py::none(),
          "precompute(H, C, D=None, options=None) -> TheoremSetupSummary; H n×n, C n×d, D n×k.")
      .def(
          "check",
          [](LockedChecker& self, py::handle A, py::handle b, py::handle q, bool return_solutions) -> py::object {
            auto lock = self.lock();
            if (!self.checker.ready()) throw py::value_error("TheoremChecker.check: call precompute first");
            const Demand demand = demand_args(self.checker.factor().n(), A, b, q);
            TheoremSolutions solutions;
            TheoremCheck result;
            {
              py::gil_scoped_release release;
              result = self.checker.check(demand.A, demand.b, demand.q, return_solutions ? &solutions : nullptr);
            }
            if (!return_solutions) return py::cast(result);
            return py::make_tuple(result, solutions);
          },
          py::arg("A"), py::arg("b"), py::arg("q"), py::arg("return_solutions") = false,
          "check(A, b, q, return_solutions=False) -> TheoremCheck or (TheoremCheck, TheoremSolutions)\n\n"
          "A: n×m (sparse or dense), b: (m,), q: (n,).")
      .def_property_readonly("ready", [](LockedChecker& self) { return self.lock(), self.checker.ready(); })
      .def_property_readonly("factor", [](LockedChecker& self) { return self.lock(), self.checker.factor(); },
                             "A copy of the PsdFactor of H.")
      .def_property_readonly("design", [](LockedChecker& self) { return self.lock(), self.checker.design(); },
                             "A copy of the WhitenedDesign.");

  m.def(
      "check_theorem",
      [](py::handle H, py::handle C, py::handle D, py::handle A, py::handle b, py::handle q, py::handle options,
         bool return_solutions) -> py::object {
        const auto design = design_args<double>(H, C, D);
        const Demand demand = demand_args(design.H.rows(), A, b, q);
        const auto opts = options_arg<QuotientOptions>("options", options);
        TheoremSolutions solutions;
        TheoremCheck result;
        {
          py::gil_scoped_release release;
          result = check_theorem(design.H, design.C, design.D, demand.A, demand.b, demand.q, opts,
                                 return_solutions ? &solutions : nullptr);
        }
        if (!return_solutions) return py::cast(result);
        return py::make_tuple(result, solutions);
      },
      py::arg("H"), py::arg("C"), py::arg("D"), py::arg("A"), py::arg("b"), py::arg("q"),
      py::arg("options") = py::none(), py::arg("return_solutions") = false,
      "check_theorem(H, C, D, A, b, q, options=None, return_solutions=False) -> TheoremCheck\n\n"
      "One-off precompute + check: H n×n, C n×d, D n×k, A n×m, b (m,), q (n,).");
}

}  // namespace

void bind_analysis(py::module_& m) {
  bind_full_solve(m);
  bind_quotient(m);
  bind_whitening(m);
  bind_theorem(m);
  bind_theorem_checker(m);
}

}  // namespace qpreduce::python
