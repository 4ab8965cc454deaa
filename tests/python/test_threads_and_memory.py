"""The GIL is released in precompute; a shared solver stays consistent; no
leak over 10⁴ solves."""

import sys
import threading

import numpy as np

import qpreduce
from conftest import rss_growth
from qpreduce import families


def small_ready_solver(seed=1):
    family = families.make_gmrf(families.GmrfOptions(nx=20, ny=20, candidates=60, observed=12, seed=seed))
    solver = qpreduce.SubspaceSolver()
    solver.precompute(family.H, family.C, family.D, families.recommended_options(family)).raise_if_failed()
    return family, solver


def test_solves_run_while_another_solver_precomputes():
    big = families.make_gmrf(families.GmrfOptions(nx=200, ny=200, candidates=400, seed=3))
    family, solver = small_ready_solver()
    demand = families.make_demand(family, 0)
    solver.set_constraints(demand.A).raise_if_failed()
    expected = solver.solve_in_D(demand.b, demand.Y)

    result = {}
    started = threading.Event()

    def precompute():
        started.set()
        result["summary"] = qpreduce.SubspaceSolver().precompute(big.H, big.C, big.D)

    thread = threading.Thread(target=precompute)
    thread.start()
    started.wait()
    solves = 0
    while thread.is_alive():
        w = solver.solve_in_D(demand.b, demand.Y)
        assert np.array_equal(w, expected)
        solves += 1
    thread.join()
    assert result["summary"].ok(), result["summary"].brief_report()
    # A precompute of 40,000 unknowns lasts tens of milliseconds at least; had it
    # held the GIL, no solve could have run meanwhile.
    assert solves >= 100, f"only {solves} solves during a {result['summary'].total_seconds:.3f} s precompute"


def test_one_solver_shared_by_threads_gives_consistent_answers():
    family, solver = small_ready_solver(seed=2)
    demands = [families.make_demand(family, i) for i in range(2)]
    assert demands[0].b.shape == demands[1].b.shape
    # solve_in_D(b₀, Y₀) under either constraint set; a solve must see one
    # whole set (the lock), never half of each.
    answers = []
    for demand in demands:
        solver.set_constraints(demand.A).raise_if_failed()
        answers.append(solver.reconstruct(solver.solve_in_D(demands[0].b, demands[0].Y)))
    assert not np.array_equal(answers[0], answers[1])
    stop = threading.Event()
    errors = []

    def switch_constraints():
        i = 0
        while not stop.is_set():
            solver.set_constraints(demands[i % 2].A)
            i += 1

    thread = threading.Thread(target=switch_constraints)
    thread.start()
    try:
        for i in range(2000):
            X = solver.reconstruct(solver.solve_in_D(demands[0].b, demands[0].Y))
            if not any(np.array_equal(X, answer) for answer in answers):
                errors.append(i)
    finally:
        stop.set()
        thread.join()
    assert not errors, f"{len(errors)} of 2000 answers match neither constraint set"


def test_no_leak_over_ten_thousand_solves():
    family, solver = small_ready_solver(seed=4)
    demand = families.make_demand(family, 1)
    b, Y = np.array(demand.b), np.array(demand.Y)
    solver.set_constraints(demand.A).raise_if_failed()
    refcounts = (sys.getrefcount(b), sys.getrefcount(Y))

    def run(count):
        for i in range(count):
            X = solver.reconstruct(solver.solve_in_D(b, Y))
            if i % 100 == 0:
                solver.set_constraints(demand.A)
                solver.subspace  # a copy of N and UD, freed at once
        return X

    growth = rss_growth(run)
    # Each iteration allocates w and X (≈ 4 KB); leaking either would add ≥ 40 MB.
    assert growth < 2 * 1024 * 1024, f"RSS grew by {growth / 1024:.0f} KiB over 10⁴ solves"
    assert (sys.getrefcount(b), sys.getrefcount(Y)) == refcounts
