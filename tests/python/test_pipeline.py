"""qpreduce.deform.run_scenario: the pipeline `qpr deform` runs (precompute,
the on-site step, the frames, settle, refine) in one call — the same frames
as a Deformer driven by hand, settle and refine when asked, and errors."""

import math

import numpy as np
import pytest

import qpreduce
from qpreduce import deform

from test_deform import OPTIONS, bend, make_deformer, small_cylinder


def scenario(frames=3):
    V, F, sel = small_cylinder()
    return deform.sel_def_scenario(V, F, sel, bend(math.pi / 3), frames=frames)


def test_run_scenario_gives_the_frames_of_a_deformer_driven_by_hand():
    sc = scenario()
    options = deform.ScenarioRunOptions(deformer=deform.DeformerOptions(**OPTIONS))
    poses, summary = deform.run_scenario(sc, options)
    assert summary.ok() and summary.stage == deform.ScenarioStage.Done
    assert len(summary.frames) == 3 and len(summary.handle_residual) == 3
    assert summary.options.rotational_proxies == options.deformer.rotational_proxies  # no scene override
    assert poses["settled"] is None and poses["refined"] is None
    deformer, _ = make_deformer(frames=3)
    for targets in sc.frames:
        V = deformer.frame(targets)
    np.testing.assert_allclose(poses["last"], V, rtol=0, atol=1e-12 * summary.diagonal)
    assert summary.arap_energy == pytest.approx(deform.arap_energy(sc.model, poses["last"]), rel=1e-12)
    report = summary.to_dict()
    assert report["stage"] == "done" and report["frames"] == 3
    assert report["precompute"]["vertices"] == sc.model.V.shape[0]


def test_run_scenario_settles_and_refines_when_asked():
    sc = scenario()
    options = deform.ScenarioRunOptions(deformer=deform.DeformerOptions(**OPTIONS),
                                        refine=deform.RefineOptions(threads=1))
    poses, summary = deform.run_scenario(sc, options)
    assert summary.ok() and summary.settled and summary.refined
    assert summary.settle.fixed_point_residual <= options.settle_tolerance
    settled = deform.arap_energy(sc.model, poses["settled"])
    assert summary.refine.initial_energy == pytest.approx(settled, rel=1e-9)
    assert summary.refine.arap_energy <= settled
    assert summary.arap_energy == pytest.approx(deform.arap_energy(sc.model, poses["refined"]), rel=1e-12)


def test_run_scenario_refuses_bad_options_with_their_names():
    sc = scenario(frames=1)
    with pytest.raises(ValueError, match="settle_rounds must be ≥ 1, got 0"):
        deform.run_scenario(sc, deform.ScenarioRunOptions(settle_rounds=0))
    with pytest.raises(TypeError, match="options: expected ScenarioRunOptions"):
        deform.run_scenario(sc, deform.DeformerOptions())
    with pytest.raises(ValueError, match="settle_tolerance must be finite"):
        deform.ScenarioRunOptions(settle_tolerance=math.nan).validate()
