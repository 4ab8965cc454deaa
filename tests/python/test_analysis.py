"""The full-space reference, the quotient analysis and the generators from Python."""

import numpy as np
import pytest

import qpreduce
from conftest import RandomProblem, relative_error
from qpreduce import families, generators


def test_solve_full_matches_scipy_kkt(problem):
    X, summary = qpreduce.solve_full(problem.H, problem.A, problem.b, problem.q)
    assert summary.ok(), summary.brief_report()
    assert relative_error(X, problem.kkt_solution()) <= 1e-10


def test_solve_full_failure_is_a_summary():
    problem = RandomProblem(seed=1)
    A = np.hstack([problem.A, problem.A[:, :1]])  # rank deficient
    b = np.concatenate([problem.b, problem.b[:1]])
    X, summary = qpreduce.solve_full(problem.H, A, b, problem.q)
    assert X is None and not summary.usable()
    with pytest.raises(qpreduce.NumericalError) as error:
        summary.raise_if_failed()
    assert error.value.status == summary.status


def test_factor_and_distance():
    problem = RandomProblem(seed=2, nullity=3)
    factor, summary = qpreduce.factor_psd(problem.H)
    assert summary.ok() and factor.nullity == 3 and factor.rank == problem.n - 3
    H = problem.H.toarray()
    assert np.linalg.norm(factor.L.T @ factor.L - H) <= 1e-12 * np.linalg.norm(H)
    x, y = np.arange(problem.n, dtype=float), np.ones(problem.n)
    expected = np.sqrt((x - y) @ H @ (x - y))
    assert abs(factor.distance(x, y) - expected) <= 1e-12 * expected
    assert abs(qpreduce.h_distance(problem.H, x, y) - expected) <= 1e-12 * expected


def test_theorem_checker_bound_holds_on_trials():
    for family in generators.theorem_families():
        trial = generators.theorem_problem(family, 30, 0.05, 3)
        checker = qpreduce.TheoremChecker()
        checker.precompute(trial.H, trial.C, trial.D).raise_if_failed()
        check, solutions = checker.check(trial.A, trial.b, trial.q, return_solutions=True)
        assert check.status == qpreduce.TheoremStatus.Applies, check.message
        assert not check.theorem_violation() and not check.practical_violation()
        assert check.theorem_error <= check.bound.bound + check.slack
        assert solutions.X_min.shape == (trial.n,)
        assert "TheoremBound(status=TheoremStatus.Applies" in repr(check.bound)


def test_in_design_family_demand_is_exact():
    family = families.make_gmrf(families.GmrfOptions(nx=20, ny=20, candidates=50, observed=10, ridge=0.1, seed=2))
    demand = families.make_demand(family, 5)
    assert demand.in_design and demand.A.shape == (400, 10) and demand.A_c.shape == (50, 10)
    solver = qpreduce.SubspaceSolver()
    solver.precompute(family.H, family.C, family.D, families.recommended_options(family)).raise_if_failed()
    solver.set_constraints_in_design(demand.A_c).raise_if_failed()
    X = solver.reconstruct(solver.solve_in_D(demand.b, demand.Y))
    X_full, summary = qpreduce.solve_full(family.H, demand.A, demand.b, demand.q)
    assert summary.ok()
    assert relative_error(X, X_full) <= 1e-10


def test_generators_are_seeded():
    H1, K1 = generators.random_psd_with_condition(20, 2, 1e3, 9)
    H2, _ = generators.random_psd_with_condition(20, 2, 1e3, 9)
    assert (H1 != H2).nnz == 0 and K1.shape == (20, 2)
    assert np.linalg.norm(H1 @ K1) <= 1e-12 * 20
    L = generators.grid_laplacian_2d(4, 5)
    assert L.shape == (20, 20) and abs(L.sum()) <= 1e-12
