"""qpreduce.deform.arap and ArapSolver, in libigl's terms: handles named at
precompute are met exactly, the one-call solve and the solver's refine reach
the same shape, libigl-shaped inputs are accepted and wrong ones named, and a
result whose meaning changed warns (QpreduceWarning) or raises under strict."""

import warnings

import numpy as np
import pytest

import qpreduce
from qpreduce import deform


def diagonal(V):
    return float(np.linalg.norm(V.max(axis=0) - V.min(axis=0)))


def bent(V, b, noise=0.0, seed=0):
    """Targets for b: the rest shape bent about x, growing along z, plus noise."""
    z = V[b, 2]
    t = (z - V[:, 2].min()) / np.ptp(V[:, 2])
    out = V[b].copy()
    c, s = np.cos(0.8 * t), np.sin(0.8 * t)
    out[:, 1], out[:, 2] = c * V[b, 1] - s * V[b, 2], s * V[b, 1] + c * V[b, 2]
    rng = np.random.default_rng(seed)
    return out + noise * diagonal(V) * rng.uniform(-1, 1, out.shape)


@pytest.fixture(scope="module")
def cylinder():
    V, F = deform.shapes.capped_cylinder(1.0, 6.0, 16, 24)
    b = np.flatnonzero((V[:, 2] < 0.3) | (V[:, 2] > 5.7))  # both ends, as a libigl user holds them
    return V, F, b, bent(V, b)


@pytest.mark.parametrize("shape", ["surface", "tets"])
def test_solver_meets_random_targets_exactly(shape):
    if shape == "surface":
        V, F = deform.shapes.capped_cylinder(1.0, 6.0, 16, 24)
    else:
        V, F = deform.shapes.box_tets(1.0, 1.0, 4.0, 3, 3, 12)
    rng = np.random.default_rng(5)
    b = rng.choice(len(V), size=40, replace=False)
    bc = bent(V, b, noise=0.01, seed=1)
    solver = deform.ArapSolver(V, F, b)
    assert solver.handle_summary.ok()
    U = solver.solve(bc)
    d = diagonal(V)
    assert np.abs(U[b] - bc).max() <= 1e-8 * d
    assert solver.reconstruction_handle_error <= 1e-5 * d  # the subspace holds b: only float round-off
    assert np.linalg.norm(U - V, axis=1).max() > 1e-3 * d


def test_one_call_equals_the_solver_refined(cylinder):
    V, F, b, bc = cylinder
    tight = deform.RefineOptions(distance_tolerance=1e-7)
    U, summary = deform.arap(V, F, b, bc, options=tight, return_summary=True)
    assert summary.converged and np.abs(U[b] - bc).max() <= 1e-8 * diagonal(V)
    solver = deform.ArapSolver(V, F, b, options=deform.ArapSolverOptions(refine=tight))
    R = solver.solve(bc, refine=True)
    assert solver.last_refine.converged
    assert np.sqrt(((R - U) ** 2).sum(axis=1).mean()) <= 1e-5 * diagonal(V)


def test_libigl_shaped_inputs_are_accepted(cylinder):
    V, F, b, bc = cylinder
    reference = deform.arap(V, F, b, bc)
    for b_in in (b.astype(np.int32), b.astype(np.int64), b.astype(np.uint32), list(b)):
        for bc_in in (bc, np.asfortranarray(bc)):
            U = deform.arap(V, F.astype(np.int64), b_in, bc_in)
            np.testing.assert_array_equal(U, reference)
    # U as libigl's initial guess, written in place and returned.
    U = V.copy()
    out = deform.arap(V, F, b, bc, U)
    assert out is U and np.sqrt(((U - reference) ** 2).sum(axis=1).mean()) <= 1e-3 * diagonal(V)
    solver = deform.ArapSolver(V, np.asfortranarray(F), b.astype(np.int64))
    out = np.empty_like(V)
    assert solver.solve(np.asfortranarray(bc), out) is out


def test_wrong_inputs_are_named(cylinder):
    V, F, b, bc = cylinder
    with pytest.raises(TypeError, match="^b:"):
        deform.arap(V, F, b.astype(np.float64), bc)
    with pytest.raises(ValueError, match="^b:"):
        deform.arap(V, F, b[None, :], bc)
    with pytest.raises(ValueError, match="^bc:"):
        deform.arap(V, F, b, bc[:-1])
    with pytest.raises(ValueError, match="^F:"):
        deform.arap(V, F[:, :2], b, bc)
    with pytest.raises(ValueError, match="twice"):
        deform.arap(V, F, np.r_[b, b[:1]], np.r_[bc, bc[:1]])
    with pytest.raises(ValueError, match=r"b\[1\]"):
        deform.arap(V, F, [0, len(V)], bc[:2])
    with pytest.raises(ValueError, match="bc.*NaN"):
        deform.arap(V, F, b, np.full_like(bc, np.nan))
    with pytest.raises(ValueError, match="^U:"):
        deform.arap(V, F, b, bc, np.zeros((3, 3)))
    solver = deform.ArapSolver(V, F, b)
    with pytest.raises(ValueError, match="^bc:"):
        solver.solve(bc[:, :2])
    assert np.abs(solver.solve(bc)[b] - bc).max() == 0.0  # a refused call loses nothing


def test_a_subspace_above_max_basis_gb_is_refused_with_its_size(cylinder):
    V, F, b, bc = cylinder
    options = deform.ArapSolverOptions(max_basis_gb=1e-6)
    with pytest.raises(qpreduce.NumericalError, match=r"held vertices.*GB.*arap\(\)") as refused:
        deform.ArapSolver(V, F, b, options=options)
    assert refused.value.status == qpreduce.Status.NotRun
    with pytest.raises(ValueError, match="max_basis_gb"):
        deform.ArapSolver(V, F, b, options=deform.ArapSolverOptions(max_basis_gb=-1.0))


def test_least_squares_handles_warn_and_raise_under_strict(cylinder):
    V, F, b, bc = cylinder
    deformer = deform.Deformer(V, F)
    deformer.precompute()
    with pytest.warns(qpreduce.QpreduceWarning, match="least-squares.*ArapSolver"):
        summary = deformer.set_handles(list(b))
    assert summary.status == qpreduce.Status.ConstraintsLeastSquares
    with pytest.warns(qpreduce.QpreduceWarning, match=r"end \d\.\d\de-\d\d of the bounding-box diagonal"):
        deformer.frame(bc)
    with warnings.catch_warnings():
        warnings.simplefilter("error", qpreduce.QpreduceWarning)
        with pytest.raises(qpreduce.QpreduceWarning):
            deformer.frame(bc)
    strict = deform.Deformer(V, F, strict=True)
    strict.precompute()
    with pytest.raises(qpreduce.NumericalError, match="least-squares") as caught:
        strict.set_handles(list(b))
    assert caught.value.status == qpreduce.Status.ConstraintsLeastSquares
    # An exact set is silent.
    exact = deform.ArapSolver(V, F, b, strict=True)
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        exact.solve(bc)


def test_a_solve_stopped_at_its_round_limit_warns(cylinder):
    V, F, b, bc = cylinder
    capped = deform.RefineOptions(max_iterations=2, newton_after=0, distance_tolerance=1e-9)
    with pytest.warns(qpreduce.QpreduceWarning, match="without converging"):
        deform.arap(V, F, b, bc, options=capped)
    with pytest.raises(qpreduce.NumericalError, match="without converging"):
        deform.arap(V, F, b, bc, options=capped, strict=True)
