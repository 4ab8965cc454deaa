// The C++ side of tests/python/test_same_as_cpp.py: runs the engine on seeded
// inputs that the Python package can make too and prints every number with
// 17 significant digits, one "key value value ..." line each.
//   python_cpp_reference family <gmrf|trajectory|portfolio> <size> <seed> <demands>
//   python_cpp_reference theorem <family> <size> <epsilon> <seed>
#include <qpreduce/problems/families.h>
#include <qpreduce/problems/generators.h>
#include <qpreduce/subspace_solver.h>
#include <qpreduce/theorem.h>

#include <cstdio>
#include <cstdlib>
#include <string>

namespace {

void print(const char* key, const qpreduce::Vector<double>& v) {
  std::printf("%s", key);
  for (Eigen::Index i = 0; i < v.size(); ++i) std::printf(" %.17g", v[i]);
  std::printf("\n");
}

int run_family(const std::string& name, long size, unsigned long seed, long demands) {
  namespace fam = qpreduce::families;
  const fam::QpFamily family = fam::make_family(fam::parse_family(name), size, seed);
  qpreduce::SubspaceSolver<double> solver;
  const auto summary = solver.precompute(family.H, family.C, family.D, fam::recommended_options(family));
  if (!summary.ok()) {
    std::fprintf(stderr, "precompute: %s\n", summary.brief_report().c_str());
    return 1;
  }
  for (long i = 0; i < demands; ++i) {
    const fam::QpDemand demand = fam::make_demand(family, static_cast<std::uint64_t>(i));
    solver.set_constraints(demand.A);
    qpreduce::Vector<double> w(solver.p()), X(solver.n());
    solver.solve_in_D(demand.b, demand.Y, w);
    solver.reconstruct(w, X);
    print("w", w);
    print("X", X);
  }
  return 0;
}

int run_theorem(const std::string& name, long size, double epsilon, unsigned long seed) {
  namespace gen = qpreduce::generators;
  const gen::TheoremTrial trial = gen::theorem_problem(gen::parse_theorem_family(name), size, epsilon, seed);
  const qpreduce::TheoremCheck check = qpreduce::check_theorem(trial.H, trial.C, trial.D, trial.A, trial.b, trial.q);
  std::printf("status %d\n", static_cast<int>(check.status));
  std::printf("bound %.17g\n", check.bound.bound);
  std::printf("rho %.17g\n", check.bound.rho);
  std::printf("practical_error %.17g\n", check.practical_error);
  std::printf("theorem_error %.17g\n", check.theorem_error);
  return 0;
}

}  // namespace

int main(int argc, char** argv) {
  const std::string mode = argc > 1 ? argv[1] : "";
  if (mode == "family" && argc == 6) {
    return run_family(argv[2], std::atol(argv[3]), std::strtoul(argv[4], nullptr, 10), std::atol(argv[5]));
  }
  if (mode == "theorem" && argc == 6) {
    return run_theorem(argv[2], std::atol(argv[3]), std::atof(argv[4]), std::strtoul(argv[5], nullptr, 10));
  }
  std::fprintf(stderr, "usage: %s family <name> <size> <seed> <demands> | theorem <family> <size> <epsilon> <seed>\n",
               argv[0]);
  return 2;
}
