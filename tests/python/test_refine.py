"""qpreduce.deform.Refiner: the full-space finish of a reduced pose — the same
converged energy from the reduced pose and from rest, one factorization per
handle set, out= without a copy, cancel from another thread, and errors."""

import math
import threading
import time

import numpy as np
import pytest

import qpreduce
from qpreduce import deform

from test_deform import bend, make_deformer, small_cylinder


@pytest.fixture(scope="module")
def posed():
    deformer, scenario = make_deformer(frames=2)
    reduced = deformer.frame(scenario.frames[-1])
    return deformer, scenario, reduced


def test_refine_from_the_reduced_pose_and_from_rest_reach_the_same_arap_energy(posed):
    _, scenario, reduced = posed
    refiner = deform.Refiner(scenario.model, deform.RefineOptions(distance_tolerance=0.0, tolerance=1e-10))
    targets = scenario.frames[-1]
    V_red, from_reduced = refiner.refine(scenario.handles, targets, reduced)
    V_rest, from_rest = refiner.refine(scenario.handles, targets)
    assert from_reduced.ok() and from_reduced.converged and from_rest.converged
    assert from_reduced.refactored and not from_rest.refactored  # same handle set: factor reused
    assert from_reduced.axis_separable and from_rest.axis_separable  # patches held: one factor for x, y, z
    assert from_reduced.arap_energy == pytest.approx(from_rest.arap_energy, rel=1e-6)
    assert from_reduced.arap_energy == pytest.approx(deform.arap_energy(scenario.model, V_red), rel=1e-12)
    # It only goes down from the reduced pose, and agrees with the plain reference.
    assert from_reduced.arap_energy <= deform.arap_energy(scenario.model, reduced) * (1 + 1e-12)
    _, reference = deform.solve_local_global(scenario.model, scenario.handles, targets,
                                             deform.ReferenceOptions(max_iterations=20000))
    assert from_reduced.arap_energy == pytest.approx(reference.energy, rel=1e-6)
    assert from_reduced.handle_residual < 1e-9
    # The readout: distances from the input pose over the diagonal, per round.
    diagonal = np.linalg.norm(scenario.model.V.max(axis=0) - scenario.model.V.min(axis=0))
    d = np.linalg.norm(V_red - reduced, axis=1) / diagonal
    assert from_reduced.max_from_input == pytest.approx(d.max(), rel=1e-9)
    assert from_reduced.rms_from_input == pytest.approx(np.sqrt(np.mean(d**2)), rel=1e-9)
    assert len(from_reduced.round_energy) == from_reduced.rounds
    assert np.all(np.diff(from_reduced.round_energy) <= 1e-12 * from_reduced.initial_energy)
    # Warm-started from the reduced pose it needs fewer rounds than from rest.
    assert from_reduced.rounds < from_rest.rounds


def test_the_default_stop_is_within_its_estimate_of_the_converged_shape(posed):
    # The default refine stops once it estimates the pose within
    # distance_tolerance (RMS / diagonal) of the converged shape; the shape
    # it returns is that close to a run to the reference test, and the
    # estimate does not claim less than the distance is.
    _, scenario, reduced = posed
    targets = scenario.frames[-1]
    refiner = deform.Refiner(scenario.model)
    assert refiner.options.distance_tolerance == 1e-4 and refiner.options.tolerance == 0.0
    V, summary = refiner.refine(scenario.handles, targets, reduced)
    assert summary.converged and summary.estimated_distance <= 1e-4
    refiner.set_options(deform.RefineOptions(distance_tolerance=0.0, tolerance=0.0))
    tight, exact = refiner.refine(scenario.handles, targets, V)
    assert exact.converged
    diagonal = np.linalg.norm(scenario.model.V.max(axis=0) - scenario.model.V.min(axis=0))
    rms = np.sqrt(np.mean(np.sum((V - tight) ** 2, axis=1))) / diagonal
    assert rms <= 1e-4
    assert summary.estimated_distance >= 0.5 * rms
    with pytest.raises(ValueError, match="distance_tolerance"):
        deform.RefineOptions(distance_tolerance=-1.0).validate()


def test_newton_steps_reach_the_minimiser_of_the_plain_rounds(posed):
    # After newton_after rounds, trust-region Newton steps replace them; they
    # end at the classic minimiser the plain rounds reach, and say how many
    # steps and Hessian products they took.
    _, scenario, reduced = posed
    targets = scenario.frames[-1]
    assert deform.RefineOptions().newton_after == 64
    refiner = deform.Refiner(scenario.model, deform.RefineOptions(distance_tolerance=0.0, newton_after=2))
    V, newton = refiner.refine(scenario.handles, targets, reduced)
    refiner.set_options(deform.RefineOptions(distance_tolerance=0.0, anderson_window=0, newton_after=0))
    P, plain = refiner.refine(scenario.handles, targets, reduced)
    assert newton.converged and plain.converged
    assert newton.newton_steps > 0 and newton.cg_iterations >= newton.newton_steps and plain.newton_steps == 0
    assert newton.arap_energy == pytest.approx(plain.arap_energy, rel=1e-8)
    diagonal = np.linalg.norm(scenario.model.V.max(axis=0) - scenario.model.V.min(axis=0))
    assert np.sqrt(np.mean(np.sum((V - P) ** 2, axis=1))) / diagonal <= 1e-5
    assert np.all(np.diff(newton.round_energy) <= 1e-12 * newton.initial_energy)
    with pytest.raises(ValueError, match="newton_after"):
        deform.RefineOptions(newton_after=-1).validate()


def test_refine_writes_the_callers_array(posed):
    _, scenario, reduced = posed
    refiner = deform.Refiner(scenario.model)
    out = np.zeros_like(reduced)
    V, summary = refiner.refine(scenario.handles, scenario.frames[-1], reduced, out=out)
    assert V is out and summary.ok()
    expected, _ = refiner.refine(scenario.handles, scenario.frames[-1], reduced)
    assert np.array_equal(out, expected)


def test_cancel_from_another_thread_leaves_a_valid_pose():
    # From rest with plain rounds and no tolerance on a 4,802-vertex cylinder:
    # 1,681 rounds (about 10 s here) unless cancelled. (On the 322-vertex
    # fixture the rounds converged in 288 rounds, 64 ms, and on a loaded
    # machine sometimes before the first cancel() 50 ms later.)
    V0, F, sel = small_cylinder(around=60, rings=80)
    scenario = deform.sel_def_scenario(V0, F, sel, bend(math.pi / 3), frames=2)
    refiner = deform.Refiner(scenario.model, deform.RefineOptions(distance_tolerance=0.0, tolerance=0.0,
                                                                   anderson_window=0, max_iterations=1))
    # One round first: it factors the global step of this handle set, so the
    # cancelled call below starts its rounds at once.
    _, first = refiner.refine(scenario.handles, scenario.frames[-1])
    assert first.refactored and first.rounds == 1
    refiner.set_options(deform.RefineOptions(distance_tolerance=0.0, tolerance=0.0, anderson_window=0,
                                             max_iterations=1000000))
    result = {}

    def run():
        result["V"], result["summary"] = refiner.refine(scenario.handles, scenario.frames[-1])

    worker = threading.Thread(target=run)
    worker.start()
    deadline = time.monotonic() + 60
    while worker.is_alive() and time.monotonic() < deadline:
        time.sleep(0.05)
        refiner.cancel()
    worker.join(timeout=60)
    assert not worker.is_alive(), "cancel() did not stop the refine"
    summary, V = result["summary"], result["V"]
    assert summary.cancelled and not summary.converged and summary.ok()
    assert not summary.refactored
    assert np.isfinite(V).all()
    assert summary.arap_energy == pytest.approx(deform.arap_energy(scenario.model, V), rel=1e-12)
    assert len(summary.round_energy) == summary.rounds
    if summary.rounds == 0:
        # Cancelled before its first round ended (a starved worker): the input, untouched.
        assert np.array_equal(V, scenario.model.V)
    else:
        # The rest pose misses the targets (energy 0); the rounds hold them and
        # then only go down.
        assert summary.handle_residual < 1e-9
        assert np.all(np.diff(summary.round_energy) <= 1e-12 * summary.round_energy[0])
    # A later refine is not affected by the earlier cancel.
    refiner.set_options(deform.RefineOptions(tolerance=1e-8))
    _, again = refiner.refine(scenario.handles, scenario.frames[-1], V)
    assert again.converged and not again.cancelled


def test_bad_options_and_arguments_name_the_problem(posed):
    _, scenario, reduced = posed
    with pytest.raises(ValueError, match="tolerance"):
        deform.Refiner(scenario.model, deform.RefineOptions(tolerance=-1.0))
    with pytest.raises(ValueError, match="anderson_window"):
        deform.RefineOptions(anderson_window=17).validate()
    with pytest.raises(ValueError, match=r"threads must be ≥ 0 \(0: all\), got -1"):
        deform.RefineOptions(threads=-1).validate()
    refiner = deform.Refiner(scenario.model)
    with pytest.raises(ValueError, match="tolerance"):
        refiner.set_options(deform.RefineOptions(tolerance=float("nan")))
    with pytest.raises(ValueError, match=r"pose.*\(n, 3\)"):
        refiner.refine(scenario.handles, scenario.frames[-1], reduced[:-1])
    bad = reduced.copy()
    bad[3, 1] = np.nan
    with pytest.raises(ValueError, match="pose"):
        refiner.refine(scenario.handles, scenario.frames[-1], bad)
    with pytest.raises(TypeError, match="out"):
        refiner.refine(scenario.handles, scenario.frames[-1], reduced, out=np.zeros(reduced.shape, np.float32))
    with pytest.raises(TypeError):
        refiner.refine([0, 1], scenario.frames[-1])
    with pytest.raises(TypeError, match="options"):
        deform.Refiner(scenario.model, dict(tolerance=1.0))
    # The refiner still works after all of these.
    _, summary = refiner.refine(scenario.handles, scenario.frames[-1], reduced)
    assert summary.ok() and summary.converged


def test_a_failed_factorization_raises_numerical_error(posed):
    _, scenario, _ = posed
    refiner = deform.Refiner(scenario.model)
    # No handles at all: the global step is singular (the translations are free).
    with pytest.raises(qpreduce.NumericalError) as raised:
        refiner.refine(deform.Handles(), deform.HandleTargets())
    assert raised.value.status == qpreduce.Status.NumericalFailure and raised.value.message


def test_summaries_report_every_field_as_the_json_reports_do(posed):
    deformer, scenario, _ = posed
    refiner = deform.Refiner(scenario.model)
    _, summary = refiner.refine(scenario.handles, scenario.frames[-1])
    d = summary.to_dict()
    assert list(d)[:2] == ["status", "message"]
    assert d["status"] == "success"
    assert d["rounds"] == summary.rounds and d["arap_energy"] == summary.arap_energy
    assert d["rms_from_input"] == summary.rms_from_input
    assert "round_energy" not in d  # per-round histories stay on the object
    text = summary.full_report()
    assert text.startswith("status: success\n") and f"\nrounds: {summary.rounds}\n" in text
    # A nested summary comes back as a dict; brief_report says more for a SubspaceSummary.
    pre = deform.Deformer(scenario.model, deform.DeformerOptions(rotational_proxies=4, linear_proxies=4)).precompute()
    nested = pre.to_dict()["subspace"]
    assert isinstance(nested, dict) and nested["n"] == pre.subspace.n > 0
    assert pre.subspace.brief_report().startswith("success: ")
    assert "\nsubspace:\n  status: success\n" in pre.full_report()
