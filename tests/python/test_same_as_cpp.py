"""The same numbers as the C++ API on the same inputs: both sides make a
seeded family (or Theorem 4.10 trial) and run the same calls; the C++ side is
tests/python/cpp_reference.cpp (its path comes from CTest in
QPREDUCE_CPP_REFERENCE)."""

import os
import subprocess

import numpy as np
import pytest

import qpreduce
from qpreduce import families, generators

REFERENCE = os.environ.get("QPREDUCE_CPP_REFERENCE")
pytestmark = pytest.mark.skipif(not REFERENCE, reason="QPREDUCE_CPP_REFERENCE not set (run through ctest)")


def cpp_lines(*args):
    output = subprocess.run([REFERENCE, *map(str, args)], check=True, capture_output=True, text=True).stdout
    return [(line.split()[0], np.array([float(x) for x in line.split()[1:]])) for line in output.splitlines()]


@pytest.mark.parametrize("name,size", [("gmrf", 400), ("trajectory", 300), ("portfolio", 300)])
def test_family_solves_equal_the_cpp_ones(name, size):
    seed, demands = 4, 3
    family = families.make_family(families.parse_family(name), size, seed)
    solver = qpreduce.SubspaceSolver()
    solver.precompute(family.H, family.C, family.D, families.recommended_options(family)).raise_if_failed()
    expected = cpp_lines("family", name, size, seed, demands)
    assert len(expected) == 2 * demands
    for index in range(demands):
        demand = families.make_demand(family, index)
        solver.set_constraints(demand.A).raise_if_failed()
        w = solver.solve_in_D(demand.b, demand.Y)
        X = solver.reconstruct(w)
        (key_w, w_cpp), (key_X, X_cpp) = expected[2 * index], expected[2 * index + 1]
        assert (key_w, key_X) == ("w", "X")
        # Same library, same inputs, same calls: the same floating-point numbers.
        np.testing.assert_array_equal(w, w_cpp)
        np.testing.assert_array_equal(X, X_cpp)


@pytest.mark.parametrize("family_name", ["dense-psd", "grid2d"])
def test_theorem_terms_equal_the_cpp_ones(family_name):
    size, epsilon, seed = 40, 0.01, 2
    trial = generators.theorem_problem(generators.parse_theorem_family(family_name), size, epsilon, seed)
    check = qpreduce.check_theorem(trial.H, trial.C, trial.D, trial.A, trial.b, trial.q)
    expected = dict(cpp_lines("theorem", family_name, size, epsilon, seed))
    assert int(expected["status"][0]) == int(check.status)
    assert check.status == qpreduce.TheoremStatus.Applies
    for name in ("rho", "bound"):
        assert getattr(check.bound, name) == expected[name][0]
    for name in ("practical_error", "theorem_error"):
        assert getattr(check, name) == expected[name][0]
    assert check.practical_error <= check.bound.bound + check.slack
