// The seeded problem families and generators (qpreduce::problems), as the
// submodules qpreduce.families and qpreduce.generators, so that Python can
// make exactly the inputs the C++ tests make.
#include "bindings.h"
#include "fields.h"

#include <qpreduce/problems/families.h>
#include <qpreduce/problems/generators.h>

#include <pybind11/eigen.h>
#include <pybind11/stl.h>

namespace qpreduce::python {

namespace {

namespace fam = qpreduce::families;
namespace gen = qpreduce::generators;

void require_size(const char* what, Index size) {
  if (size < 0) throw py::value_error(std::string(what) + ": expected a size ≥ 0, got " + std::to_string(size));
}

// The families and their options.
void bind_family_options(py::module_& m) {
  py::enum_<fam::Family>(m, "Family", "The seeded QP families (families.h).")
      .value("Gmrf", fam::Family::Gmrf)
      .value("Trajectory", fam::Family::Trajectory)
      .value("Portfolio", fam::Family::Portfolio);
  m.def("parse_family", &fam::parse_family, py::arg("name"), "'gmrf', 'trajectory' or 'portfolio' -> Family.");

  py::class_<fam::GmrfOptions> gmrf(m, "GmrfOptions", "GMRF interpolation on an nx × ny grid.");
  Fields(gmrf, "GmrfOptions")
      .rw("nx", &fam::GmrfOptions::nx, "grid width (100)")
      .rw("ny", &fam::GmrfOptions::ny, "grid height (100)")
      .rw("candidates", &fam::GmrfOptions::candidates, "d: candidate sites (200)")
      .rw("trend", &fam::GmrfOptions::trend, "k ≤ 10: trend columns (6)")
      .rw("observed", &fam::GmrfOptions::observed, "m: sites observed per demand (40)")
      .rw("ridge", &fam::GmrfOptions::ridge, "κ² ≥ 0 (0: H singular)")
      .rw("seed", &fam::GmrfOptions::seed, "seed (1)")
      .repr()
      .keyword_init<fam::GmrfOptions>();
  py::class_<fam::TrajectoryOptions> trajectory(m, "TrajectoryOptions", "Smoothing of a path of T samples.");
  Fields(trajectory, "TrajectoryOptions")
      .rw("samples", &fam::TrajectoryOptions::samples, "T ≥ 8 (1000)")
      .rw("dims", &fam::TrajectoryOptions::dims, "coordinates per sample, 1 to 3 (2)")
      .rw("lambda_", &fam::TrajectoryOptions::lambda, "λ > 0: tracking weight (1e-2)")
      .rw("stations", &fam::TrajectoryOptions::stations, "candidate waypoint times (100)")
      .rw("waypoints", &fam::TrajectoryOptions::waypoints, "stations visited per demand (10)")
      .rw("modes", &fam::TrajectoryOptions::modes, "reference cosines per coordinate (4)")
      .rw("seed", &fam::TrajectoryOptions::seed, "seed (1)")
      .repr()
      .keyword_init<fam::TrajectoryOptions>();
  py::class_<fam::PortfolioOptions> portfolio(m, "PortfolioOptions", "Mean–variance portfolio, factor model.");
  Fields(portfolio, "PortfolioOptions")
      .rw("assets", &fam::PortfolioOptions::assets, "n_a (2000)")
      .rw("factors", &fam::PortfolioOptions::factors, "f ≥ 3 (10)")
      .rw("sectors", &fam::PortfolioOptions::sectors, "S ≥ 2 (20)")
      .rw("neutral", &fam::PortfolioOptions::neutral, "sectors constrained per demand (5)")
      .rw("risk_aversion", &fam::PortfolioOptions::risk_aversion, "γ > 0 (1)")
      .rw("seed", &fam::PortfolioOptions::seed, "seed (1)")
      .repr()
      .keyword_init<fam::PortfolioOptions>();
  py::class_<fam::DemandOptions> demand_options(m, "DemandOptions", "Off-design parts of a demand.");
  Fields(demand_options, "DemandOptions")
      .rw("outside", &fam::DemandOptions::outside, "constraints not in Span(C) (0)")
      .rw("q_noise", &fam::DemandOptions::q_noise, "relative noise added to q (0)")
      .repr()
      .keyword_init<fam::DemandOptions>();

}

// A family instance, its demands and the constructors.
void bind_family_instances(py::module_& m) {
  py::class_<fam::QpFamily>(m, "QpFamily", "One family instance: H (n×n), C (n×d), D (n×k) and demand data.")
      .def_readonly("family", &fam::QpFamily::family)
      .def_readonly("seed", &fam::QpFamily::seed)
      .def_readonly("H", &fam::QpFamily::H, "n × n scipy.sparse.csc_matrix (a copy)")
      .def_readonly("C", &fam::QpFamily::C, "n × d scipy.sparse.csc_matrix (a copy)")
      .def_readonly("D", &fam::QpFamily::D, "n × k scipy.sparse.csc_matrix (a copy)")
      .def_readonly("kernel", &fam::QpFamily::kernel, "n × ν orthonormal basis of ker H")
      .def_readonly("candidates", &fam::QpFamily::candidates)
      .def_property_readonly("n", &fam::QpFamily::n)
      .def_property_readonly("d", &fam::QpFamily::d)
      .def_property_readonly("k", &fam::QpFamily::k)
      .def_property_readonly("positive_definite", &fam::QpFamily::positive_definite)
      .def("__repr__", [](const fam::QpFamily& f) {
        return std::string("QpFamily(") + fam::to_string(f.family) + ", n=" + std::to_string(f.n()) +
               ", d=" + std::to_string(f.d()) + ", k=" + std::to_string(f.k()) + ", seed=" + std::to_string(f.seed) +
               ")";
      });
  py::class_<fam::QpDemand>(m, "QpDemand", "One demand (A n×m, b m, q = D·Y (+ noise)).")
      .def_readonly("A", &fam::QpDemand::A, "n × m scipy.sparse.csc_matrix")
      .def_readonly("A_c", &fam::QpDemand::A_c, "d × m with A = C·A_c (0 × 0 when off-design)")
      .def_readonly("b", &fam::QpDemand::b, "(m,)")
      .def_readonly("Y", &fam::QpDemand::Y, "(k,)")
      .def_readonly("q", &fam::QpDemand::q, "(n,)")
      .def_readonly("in_design", &fam::QpDemand::in_design);

  const auto released = py::call_guard<py::gil_scoped_release>();
  m.def("recommended_options", &fam::recommended_options, py::arg("family"), "SubspaceOptions suited to the family.");
  m.def("make_gmrf", &fam::make_gmrf, py::arg("options"), released, "make_gmrf(GmrfOptions) -> QpFamily");
  m.def("make_trajectory", &fam::make_trajectory, py::arg("options"), released,
        "make_trajectory(TrajectoryOptions) -> QpFamily");
  m.def("make_portfolio", &fam::make_portfolio, py::arg("options"), released,
        "make_portfolio(PortfolioOptions) -> QpFamily");
  m.def("make_family", &fam::make_family, py::arg("family"), py::arg("size"), py::arg("seed"), released,
        "make_family(Family, size, seed) -> QpFamily of roughly `size` unknowns (size ≥ 64).");
  m.def("make_demand", &fam::make_demand, py::arg("family"), py::arg("index"),
        py::arg("options") = fam::DemandOptions{}, released,
        "make_demand(family, index, options=DemandOptions()) -> QpDemand, deterministic in (seed, index, options).");
}

void bind_generators(py::module_& m) {
  const auto released = py::call_guard<py::gil_scoped_release>();
  m.def("grid_laplacian_2d", &gen::grid_laplacian_2d, py::arg("nx"), py::arg("ny"), py::arg("ridge") = 0.0, released,
        "(nx·ny) × (nx·ny) 5-point grid Laplacian + ridge·I; vertex (i, j) is i + nx·j.");
  m.def("grid_laplacian_3d", &gen::grid_laplacian_3d, py::arg("nx"), py::arg("ny"), py::arg("nz"),
        py::arg("ridge") = 0.0, released, "7-point Laplacian of an nx × ny × nz grid + ridge·I.");
  m.def(
      "random_psd",
      [](Index n, Index nullity, std::uint64_t seed) {
        Matrix<double> null_basis;
        auto H = gen::random_psd(n, nullity, seed, &null_basis);
        return std::make_pair(H, null_basis);
      },
      py::arg("n"), py::arg("nullity"), py::arg("seed"), released,
      "random_psd(n, nullity, seed) -> (H n×n sparse, null basis n×nullity)");
  m.def(
      "random_psd_with_condition",
      [](Index n, Index nullity, double condition, std::uint64_t seed) {
        Matrix<double> null_basis;
        auto H = gen::random_psd_with_condition(n, nullity, condition, seed, &null_basis);
        return std::make_pair(H, null_basis);
      },
      py::arg("n"), py::arg("nullity"), py::arg("condition"), py::arg("seed"), released,
      "random_psd_with_condition(n, nullity, condition, seed) -> (H n×n sparse, null basis n×nullity)");
  m.def("selection", &gen::selection, py::arg("n"), py::arg("rows"), "n × d selection matrix (column j: e_rows[j]).");
  m.def("random_subset", &gen::random_subset, py::arg("n"), py::arg("count"), py::arg("seed"),
        "`count` distinct sorted indices from [0, n).");
  // The Gaussian generators take sizes unchecked (Eigen asserts only).
  m.def(
      "gaussian_sparse",
      [](Index n, Index cols, std::uint64_t seed) {
        require_size("gaussian_sparse: n", n);
        require_size("gaussian_sparse: cols", cols);
        return gen::gaussian_sparse(n, cols, seed);
      },
      py::arg("n"), py::arg("cols"), py::arg("seed"), "n × cols standard normal (stored sparse).");
  m.def("grid_trend_basis", &gen::grid_trend_basis, py::arg("nx"), py::arg("ny"), py::arg("k"),
        "n × k smooth trend basis on an nx × ny grid (k ≤ 10).");
  m.def("grid_trend_basis_3d", &gen::grid_trend_basis_3d, py::arg("nx"), py::arg("ny"), py::arg("nz"), py::arg("k"),
        "n × k trend basis on an nx × ny × nz grid (k ≤ 10).");
  m.def(
      "gaussian_vector",
      [](Index n, std::uint64_t seed) {
        require_size("gaussian_vector: n", n);
        return gen::gaussian_vector(n, seed);
      },
      py::arg("n"), py::arg("seed"), "(n,) standard normal.");
  m.def(
      "gaussian_matrix",
      [](Index rows, Index cols, std::uint64_t seed) {
        require_size("gaussian_matrix: rows", rows);
        require_size("gaussian_matrix: cols", cols);
        return gen::gaussian_matrix(rows, cols, seed);
      },
      py::arg("rows"), py::arg("cols"), py::arg("seed"), "rows × cols standard normal.");

}

// The Theorem 4.10 test problems.
void bind_theorem_problems(py::module_& m) {
  const auto released = py::call_guard<py::gil_scoped_release>();
  py::enum_<gen::TheoremFamily>(m, "TheoremFamily", "Families of Theorem 4.10 trials (generators.h).")
      .value("DensePsd", gen::TheoremFamily::DensePsd)
      .value("DensePd", gen::TheoremFamily::DensePd)
      .value("Grid2d", gen::TheoremFamily::Grid2d)
      .value("Grid2dRidge", gen::TheoremFamily::Grid2dRidge)
      .value("Grid3d", gen::TheoremFamily::Grid3d)
      .value("Grid3dRidge", gen::TheoremFamily::Grid3dRidge);
  m.def("theorem_families", &gen::theorem_families, "Every TheoremFamily, in declaration order.");
  m.def("parse_theorem_family", &gen::parse_theorem_family, py::arg("name"), "'dense-psd', ... -> TheoremFamily.");
  py::class_<gen::TheoremTrial>(m, "TheoremTrial", "One seeded problem of Eq. 1 with its design spaces.")
      .def_readonly("family", &gen::TheoremTrial::family)
      .def_readonly("size", &gen::TheoremTrial::size)
      .def_readonly("epsilon", &gen::TheoremTrial::epsilon)
      .def_readonly("seed", &gen::TheoremTrial::seed)
      .def_readonly("H", &gen::TheoremTrial::H, "n × n sparse")
      .def_readonly("C", &gen::TheoremTrial::C, "n × d sparse")
      .def_readonly("D", &gen::TheoremTrial::D, "n × k sparse")
      .def_readonly("A_c", &gen::TheoremTrial::A_c, "d × m")
      .def_readonly("Y", &gen::TheoremTrial::Y, "(k,)")
      .def_readonly("E", &gen::TheoremTrial::E, "n × m")
      .def_readonly("F", &gen::TheoremTrial::F, "(n,)")
      .def_readonly("A", &gen::TheoremTrial::A, "n × m sparse, C·A_c + ε·E")
      .def_readonly("b", &gen::TheoremTrial::b, "(m,)")
      .def_readonly("q", &gen::TheoremTrial::q, "(n,), D·Y + ε·F")
      .def_readonly("kernel", &gen::TheoremTrial::kernel, "n × ν")
      .def_property_readonly("n", &gen::TheoremTrial::n)
      .def_property_readonly("d", &gen::TheoremTrial::d)
      .def_property_readonly("k", &gen::TheoremTrial::k)
      .def_property_readonly("m", &gen::TheoremTrial::m)
      .def("set_epsilon", &gen::TheoremTrial::set_epsilon, py::arg("epsilon"), "Re-forms A and q for another ε.");
  m.def("theorem_problem", &gen::theorem_problem, py::arg("family"), py::arg("size"), py::arg("epsilon"),
        py::arg("seed"), released, "theorem_problem(family, size, epsilon, seed) -> TheoremTrial (size ≥ 24).");
}

}  // namespace

void bind_problems(py::module_& m) {
  auto families = m.def_submodule("families", "Seeded non-graphics QP families (qpreduce/problems/families.h).");
  bind_family_options(families);
  bind_family_instances(families);
  auto generators = m.def_submodule("generators", "Seeded problem generators (qpreduce/problems/generators.h).");
  bind_generators(generators);
  bind_theorem_problems(generators);
}

}  // namespace qpreduce::python
