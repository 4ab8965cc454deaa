"""Every bad input raises the named exception with a message naming the argument."""

import numpy as np
import pytest
import scipy.sparse

import qpreduce
from conftest import RandomProblem


@pytest.fixture
def ready():
    problem = RandomProblem(seed=5)
    solver = qpreduce.SubspaceSolver()
    assert solver.precompute(problem.H, problem.C, problem.D).ok()
    assert solver.set_constraints(problem.A).ok()
    return problem, solver


def test_precompute_rejects_bad_matrices():
    problem = RandomProblem(seed=5)
    solver = qpreduce.SubspaceSolver()
    cases = [
        (TypeError, r"^H: expected a scipy.sparse matrix or numpy.ndarray", ([[1.0]], problem.C, problem.D)),
        (ValueError, r"^H: expected a square matrix of shape \(n, n\)", (problem.H[:, :-1], problem.C, None)),
        (ValueError, r"^C: expected shape \(n, d\) = \(60, any\), got \(59, 8\)", (problem.H, problem.C[:-1], None)),
        (ValueError, r"^D: expected shape \(n, k\) = \(60, any\), got \(3,\)", (problem.H, problem.C, problem.D[0])),
        (TypeError, r"^C: expected an array of real numbers, got dtype complex128",
         (problem.H, problem.C.astype(complex), None)),
        (TypeError, r"^options: expected SubspaceOptions or None, got ConstraintOptions",
         (problem.H, problem.C, None, qpreduce.ConstraintOptions())),
    ]
    for error, message, args in cases:
        with pytest.raises(error, match=message):
            solver.precompute(*args)
    C_nan = problem.C.copy()
    C_nan[3, 2] = np.nan
    with pytest.raises(ValueError, match="C.*NaN"):  # the C++ std::invalid_argument message
        solver.precompute(problem.H, C_nan, problem.D)
    asymmetric = problem.H.toarray()
    asymmetric[0, 1] += 1.0
    with pytest.raises(ValueError, match="symmetric"):
        solver.precompute(asymmetric, problem.C, problem.D)
    with pytest.raises(ValueError):
        solver.precompute(problem.H, problem.C, problem.D, qpreduce.SubspaceOptions(block_size=0))
    assert not solver.ready


def test_calls_before_precompute_raise_value_error():
    solver = qpreduce.SubspaceSolver()
    with pytest.raises(ValueError, match="precompute"):
        solver.set_constraints(np.zeros((0, 1)))
    with pytest.raises(ValueError, match="set_constraints"):
        solver.solve_in_D(np.zeros(0), np.zeros(0))
    with pytest.raises(ValueError, match="set_constraints"):
        solver.solve(np.zeros(0), np.zeros(0))


def test_set_constraints_rejects_bad_matrices(ready):
    problem, solver = ready
    with pytest.raises(ValueError, match=r"^A: expected shape \(n, m\) = \(60, any\), got \(59, 5\)"):
        solver.set_constraints(problem.A[:-1])
    with pytest.raises(ValueError, match=r"^A_c: expected shape \(d, m\) = \(8, any\), got \(7, 5\)"):
        solver.set_constraints_in_design(problem.A_c[:-1])
    A = problem.A.copy()
    A[0, 0] = np.inf
    with pytest.raises(ValueError, match="NaN"):
        solver.set_constraints(scipy.sparse.csr_matrix(A))
    with pytest.raises(TypeError, match="^options: expected ConstraintOptions"):
        solver.set_constraints(problem.A, qpreduce.SubspaceOptions())


def test_solve_rejects_bad_vectors(ready):
    problem, solver = ready
    b, Y = problem.b, problem.Y
    cases = [
        (TypeError, r"^b: expected a numpy.ndarray of float64 with shape \(m,\) = \(5,\), got list", (list(b), Y)),
        (TypeError, r"^Y: expected a numpy.ndarray of float64 with shape \(k,\) = \(3,\), got dtype float32",
         (b, Y.astype(np.float32))),
        (TypeError, r"^Y: .* got dtype int64", (b, np.arange(3))),
        (ValueError, r"^b: expected .* shape \(m,\) = \(5,\), got \(4,\)", (b[:4], Y)),
        (ValueError, r"^b: expected .* got \(5, 1\)", (b.reshape(5, 1), Y)),
        (ValueError, r"^b: expected a contiguous array", (np.repeat(b, 2)[::2], Y)),
        (ValueError, r"^Y: contains NaN or infinite entries", (b, np.array([1.0, np.nan, 0.0]))),
    ]
    for error, message, args in cases:
        with pytest.raises(error, match=message):
            solver.solve_in_D(*args)
    with pytest.raises(ValueError, match=r"^q_r: expected .* shape \(p,\) = \(11,\)"):
        solver.solve(b, Y)
    with pytest.raises(ValueError, match=r"^out: expected .* shape \(p,\) = \(11,\), got \(10,\)"):
        solver.solve_in_D(b, Y, out=np.empty(10))
    read_only = np.empty(solver.p)
    read_only.flags.writeable = False
    with pytest.raises(ValueError, match="^out: the array is read-only"):
        solver.solve_in_D(b, Y, out=read_only)
    q_r = solver.reduce_linear_term_in_D(Y)
    with pytest.raises(ValueError, match="^out: shares memory with q_r"):
        solver.solve(b, q_r, out=q_r)
    with pytest.raises(ValueError, match=r"^w: expected .* shape \(p,\) = \(11,\)"):
        solver.reconstruct(np.zeros(3))
    with pytest.raises(ValueError, match=r"^q: expected .* shape \(n,\) = \(60,\)"):
        solver.reduce_linear_term(np.zeros(3))
    with pytest.raises(TypeError, match=r"^b: expected a numpy.ndarray of float32"):
        solver32 = qpreduce.SubspaceSolver32()
        assert solver32.precompute(problem.H + scipy.sparse.identity(60), problem.C, problem.D).ok()
        assert solver32.set_constraints(problem.A).ok()
        solver32.solve_in_D(b, Y.astype(np.float32))


def test_analysis_and_generators_reject_bad_input():
    problem = RandomProblem(seed=5)
    with pytest.raises(ValueError, match=r"^b: expected shape \(m,\) = \(5,\), got \(4,\)"):
        qpreduce.solve_full(problem.H, problem.A, problem.b[:4], problem.q)
    with pytest.raises(ValueError, match=r"^H: expected a square matrix"):
        qpreduce.factor_psd(problem.C)
    factor, summary = qpreduce.factor_psd(problem.H)
    assert summary.ok()
    with pytest.raises(ValueError, match=r"^M: expected shape \(n, c\) = \(60, any\)"):
        factor.whiten(np.zeros((3, 2)))
    with pytest.raises(ValueError, match=r"^x: expected shape \(n,\) = \(60,\)"):
        factor.distance(np.zeros(3), np.zeros(60))
    with pytest.raises(ValueError, match="TheoremChecker.check: call precompute first"):
        qpreduce.TheoremChecker().check(problem.A, problem.b, problem.q)
    with pytest.raises(ValueError, match="gmrf"):
        qpreduce.families.parse_family("nope")
    with pytest.raises(ValueError):
        qpreduce.generators.theorem_problem(qpreduce.generators.TheoremFamily.DensePsd, 10, 0.0, 1)
    for call, message in [(lambda: qpreduce.generators.gaussian_vector(-5, 1), "^gaussian_vector: n"),
                          (lambda: qpreduce.generators.gaussian_matrix(2, -1, 1), "^gaussian_matrix: cols"),
                          (lambda: qpreduce.generators.gaussian_sparse(-3, 2, 1), "^gaussian_sparse: n"),
                          (lambda: qpreduce.generators.selection(3, [10]), "row 10 out of range")]:
        with pytest.raises(ValueError, match=message):
            call()
