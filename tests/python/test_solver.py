"""SubspaceSolver against SciPy's full KKT solve and against its own invariants."""

import numpy as np
import pytest
import scipy.sparse

import qpreduce
from conftest import RandomProblem, relative_error


def precomputed(problem, H=None, C=None, D=None, solver_type=qpreduce.SubspaceSolver):
    solver = solver_type()
    summary = solver.precompute(problem.H if H is None else H, problem.C if C is None else C,
                                problem.D if D is None else D)
    assert summary.ok(), summary.brief_report()
    return solver


def test_in_span_demand_matches_scipy_kkt(problem):
    solver = precomputed(problem)
    assert (solver.n, solver.d, solver.k, solver.p) == (problem.n, problem.d, problem.k, problem.d + problem.k)
    summary = solver.set_constraints(problem.A)
    assert summary.ok() and summary.m == problem.m and summary.rank == problem.m
    X = solver.reconstruct(solver.solve_in_D(problem.b, problem.Y))
    assert relative_error(X, problem.kkt_solution()) <= 1e-10


@pytest.mark.parametrize("fast_path,explicit", [(True, False), (True, True), (False, False)])
def test_every_path_and_input_format_gives_the_kkt_answer(fast_path, explicit):
    problem = RandomProblem(seed=7)
    H = problem.H
    # H as COO with int64 indices, C as CSR, D dense: every accepted format.
    H64 = H.tocoo()
    H64.row, H64.col = H64.row.astype(np.int64), H64.col.astype(np.int64)
    solver = precomputed(problem, H=H64, C=scipy.sparse.csr_matrix(problem.C), D=problem.D)
    options = qpreduce.ConstraintOptions(fast_path=fast_path, explicit_operators=explicit)
    assert solver.set_constraints(problem.A, options).ok()
    reference = problem.kkt_solution()
    w = solver.solve_in_D(problem.b, problem.Y)
    assert relative_error(solver.reconstruct(w), reference) <= 1e-10
    # q given in full: solve(b, Bᵀq) is the same answer.
    q_r = solver.reduce_linear_term(problem.q)
    assert np.allclose(q_r, solver.reduce_linear_term_in_D(problem.Y), rtol=1e-12, atol=1e-12 * np.abs(q_r).max())
    assert relative_error(solver.reconstruct(solver.solve(problem.b, q_r)), reference) <= 1e-10


def test_constraints_in_design_equal_constraints_in_full(problem):
    solver = precomputed(problem)
    assert solver.set_constraints_in_design(problem.A_c).ok()
    w_design = solver.solve_in_D(problem.b, problem.Y)
    assert solver.set_constraints(problem.A).ok()
    w_full = solver.solve_in_D(problem.b, problem.Y)
    assert relative_error(w_design, w_full) <= 1e-10
    assert relative_error(solver.reconstruct(w_design), problem.kkt_solution()) <= 1e-10


def test_soft_constraints_solve_the_penalised_reduced_system(problem):
    solver = precomputed(problem)
    delta = 10.0
    summary = solver.set_constraints(problem.A, qpreduce.ConstraintOptions(soft=True, delta=delta))
    assert summary.ok(), summary.brief_report()
    w = solver.solve_in_D(problem.b, problem.Y)
    Hr, Ar = solver.reduced_hessian, solver.reduced_constraints
    q_r = solver.reduced_linear_map @ problem.Y
    residual = (Hr + 2 * delta * Ar.T @ Ar) @ w - (q_r + 2 * delta * Ar.T @ problem.b)
    scale = np.linalg.norm(Hr + 2 * delta * Ar.T @ Ar) * np.linalg.norm(w) + np.linalg.norm(q_r)
    assert np.linalg.norm(residual) <= 1e-12 * scale
    assert not np.allclose(problem.A.T @ solver.reconstruct(w), problem.b)  # soft: not exactly feasible


def test_no_D_columns_and_general_q():
    problem = RandomProblem(seed=11, nullity=0)
    solver = qpreduce.SubspaceSolver()
    assert solver.precompute(problem.H, problem.C).ok()  # D = None: k = 0
    assert solver.k == 0 and solver.p == problem.d
    assert solver.set_constraints(problem.A).ok()
    w = solver.solve_in_D(problem.b, np.zeros(0))
    # With q = 0 the in-span demand is exact.
    zero = np.zeros(problem.n)
    assert relative_error(solver.reconstruct(w), problem.kkt_solution(q=zero)) <= 1e-10


def test_restore_reproduces_the_solver(problem):
    solver = precomputed(problem)
    restored = qpreduce.SubspaceSolver()
    parts = solver.subspace
    restored.restore(parts.N, parts.UD, solver.reduced_hessian, solver.reduced_linear_map)
    assert restored.ready
    for s in (solver, restored):
        assert s.set_constraints(problem.A).ok()
    w0, w1 = solver.solve_in_D(problem.b, problem.Y), restored.solve_in_D(problem.b, problem.Y)
    assert relative_error(w1, w0) <= 1e-12


def test_out_arguments_are_written_in_place(problem):
    solver = precomputed(problem)
    solver.set_constraints(problem.A)
    w = np.empty(solver.p)
    assert solver.solve_in_D(problem.b, problem.Y, out=w) is w
    X = np.empty(solver.n)
    assert solver.reconstruct(w, out=X) is X
    assert relative_error(X, problem.kkt_solution()) <= 1e-10


@pytest.mark.parametrize("seed", [0, 1])
def test_float32_solver_is_accurate_to_single_precision(seed):
    # PD H: single precision cannot tell a PSD H from a slightly indefinite one.
    problem = RandomProblem(seed=seed, nullity=0)
    solver = precomputed(problem, solver_type=qpreduce.SubspaceSolver32)
    assert solver.set_constraints(problem.A).ok()
    w = solver.solve_in_D(problem.b.astype(np.float32), problem.Y.astype(np.float32))
    X = solver.reconstruct(w)
    assert X.dtype == np.float32
    # Single precision on a condition-1e3 problem: a few thousand ε₃₂.
    assert relative_error(X.astype(np.float64), problem.kkt_solution()) <= 1e-3


def test_summaries_and_options_read_well():
    options = qpreduce.SubspaceOptions(rho_scale=2.0, augment=False)
    assert options.rho_scale == 2.0 and not options.augment
    assert repr(options).startswith("SubspaceOptions(backend=Backend.Auto, rho_scale=2.0")
    assert "soft=True" in repr(qpreduce.ConstraintOptions(soft=True))
    with pytest.raises(TypeError, match="unknown keyword 'rho'"):
        qpreduce.SubspaceOptions(rho=1.0)
    with pytest.raises(ValueError):
        qpreduce.ConstraintOptions(drop_tolerance=2.0).validate()
    help_text = qpreduce.SubspaceSolver.solve_in_D.__doc__
    assert "b: (m,)" in help_text and "Y: (k,)" in help_text


def test_numerical_failure_is_a_summary_and_raise_if_failed_raises():
    problem = RandomProblem(seed=3, nullity=0)
    indefinite = problem.H - 0.5 * scipy.sparse.identity(problem.n, format="csc")
    solver = qpreduce.SubspaceSolver()
    summary = solver.precompute(indefinite, problem.C, problem.D)
    assert summary.status == qpreduce.Status.IndefiniteH and not solver.ready
    with pytest.raises(qpreduce.NumericalError) as error:
        summary.raise_if_failed()
    assert error.value.status == qpreduce.Status.IndefiniteH and error.value.message == summary.message
    ok = precomputed(problem).set_constraints(problem.A)
    assert ok.raise_if_failed() is ok
