"""The examples in python/examples/, each run on a small size."""

import importlib.util
import os

import numpy as np
import pytest

from qpreduce import deform

EXAMPLES = os.path.join(os.path.dirname(os.path.abspath(__file__)), "..", "..", "python", "examples")


def load(name):
    spec = importlib.util.spec_from_file_location(name, os.path.join(EXAMPLES, name + ".py"))
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


def test_gmrf_interpolation_matches_spsolve_of_the_kkt_system():
    worst = load("gmrf_interpolation").main(["--nx", "30", "--ny", "25", "--candidates", "60", "--observed", "12",
                                             "--demands", "3"])
    # In-span demands: the reduced answer is the exact one up to round-off.
    assert worst < 1e-9


def test_theorem_bound_holds_and_plots(tmp_path):
    path = tmp_path / "theorem.png"
    rows, violations = load("theorem_bound").main(["--trials", "24", "--out", str(path)])
    assert violations == 0 and len(rows) > 12
    assert all(bound >= error for _, error, bound in rows)
    assert path.stat().st_size > 10_000


def test_deform_cactus_writes_frames_and_a_figure(tmp_path):
    residual = load("deform_cactus").main(["--builtin", "--around", "16", "--rings", "20", "--frames", "4",
                                           "--rotational-proxies", "8", "--linear-proxies", "10",
                                           "--out", str(tmp_path)])
    frames = sorted(p for p in os.listdir(tmp_path) if p.endswith(".obj") and "refined" not in p)
    assert len(frames) == 4
    V, F = deform.read_mesh(str(tmp_path / frames[-1]))
    rest, F0 = deform.shapes.capped_cylinder(1.0, 12.0, 16, 20)
    assert np.array_equal(F, F0) and not np.allclose(V, rest)
    # The refined last pose: same mesh, lower classic ARAP energy than the reduced one.
    R, _ = deform.read_mesh(str(tmp_path / "cylinder_refined.obj"))
    model = deform.Model(rest, F0)
    assert deform.arap_energy(model, R) < deform.arap_energy(model, V)
    assert residual < 1e-5  # the handle patch follows its path (float reconstruction)
    assert (tmp_path / "cylinder.png").stat().st_size > 10_000


def test_arap_one_call_meets_the_handles_and_its_refine_reaches_the_one_call_shape(tmp_path):
    result = load("arap_one_call").main(["--builtin", "--around", "16", "--rings", "24", "--solves", "2",
                                         "--out", str(tmp_path)])
    assert result["converged"]
    assert result["one_call_handle_error"] <= 1e-8 and result["handle_error"] <= 1e-8
    # The reduced shape is the E′ model's (a few % of the diagonal away); the
    # refine and the one call stop within 1e-4 of the converged shape each.
    assert result["reduced_rms"] > result["refined_rms"]
    assert result["refined_rms"] <= 1e-3
    assert sorted(p.name for p in tmp_path.iterdir()) == ["one_call.off", "reduced.off", "refined.off"]
