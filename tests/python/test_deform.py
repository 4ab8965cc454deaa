"""qpreduce.deform: mesh files, the Deformer (precompute, handles, frames into
the caller's array, save/load), the models, the references, and the errors."""

import math
import warnings

import numpy as np
import pytest

import qpreduce
from qpreduce import deform

# float64 ε; the reconstruction runs in float (deformer.h), whose ε is 2⁻²⁴.
FLOAT_EPS = 2.0**-24


def small_cylinder(around=16, rings=20):
    """A 12-long capped cylinder (322 vertices): base fixed, top cap a handle."""
    V, F = deform.shapes.capped_cylinder(1.0, 12.0, around, rings)
    sel = np.ones(len(V), dtype=np.int32)
    sel[V[:, 2] < 0.6] = 0
    sel[V[:, 2] > 11.4] = 2
    return V, F, sel


def bend(angle):
    """4×4 map of the top cap: rotated by `angle` about x around z = 12."""
    c, s = math.cos(angle), math.sin(angle)
    R = np.array([[1, 0, 0], [0, c, -s], [0, s, c]])
    M = np.eye(4)
    M[:3, :3] = R
    M[:3, 3] = np.array([0, 0, 12.0]) - R @ np.array([0, 0, 12.0]) + np.array([0, -2.0 * math.sin(angle), 0])
    return M


# No time budget: tests that compare two runs' frames must not depend on how
# loaded the machine is (the rounds still stop at the default tolerance).
OPTIONS = dict(rotational_proxies=8, linear_proxies=10, time_budget=0.0)


def make_deformer(frames=4, **options):
    V, F, sel = small_cylinder()
    scenario = deform.sel_def_scenario(V, F, sel, bend(math.pi / 3), frames=frames)
    deformer = deform.Deformer(scenario.model, deform.DeformerOptions(**{**OPTIONS, **options}))
    deformer.precompute()
    deformer.set_handles(scenario.handles, options=scenario.constraints)
    return deformer, scenario


# ---- mesh files ----


@pytest.mark.parametrize("ext", ["obj", "off", "ply"])
def test_triangle_mesh_round_trip_is_exact(tmp_path, ext):
    V, F, _ = small_cylinder()
    V = V + 1e-3 * np.random.default_rng(0).standard_normal(V.shape)  # non-round doubles
    path = str(tmp_path / f"mesh.{ext}")
    deform.write_mesh(path, V, F)
    V2, F2 = deform.read_mesh(path)
    assert V2.dtype == np.float64 and V2.shape == V.shape and F2.dtype == np.int32
    assert np.array_equal(V2, V) and np.array_equal(F2, F)


@pytest.mark.parametrize("ext", ["mesh", "node"])
def test_tet_mesh_round_trip(tmp_path, ext):
    V, T = deform.shapes.box_tets(1.0, 2.0, 0.5, 2, 3, 1)
    path = str(tmp_path / f"box.{ext}")
    deform.write_tet_mesh(path, V, T)
    V2, T2 = deform.read_tet_mesh(path)
    assert np.array_equal(V2, V) and np.array_equal(T2, T)
    assert len(deform.read_tet_mesh(path, boundary=True)) == 3


def test_reader_errors_are_io_errors_naming_the_file(tmp_path):
    path = tmp_path / "bad.off"
    path.write_text("OFF\n3 1 0\n0 0 0\n1 0 x\n0 1 0\n3 0 1 2\n")
    with pytest.raises(deform.IoError, match="bad.off:4: malformed number"):
        deform.read_mesh(str(path))
    with pytest.raises(OSError):
        deform.read_mesh(str(tmp_path / "missing.obj"))


def test_writer_refuses_bad_arrays(tmp_path):
    V, F, _ = small_cylinder()
    with pytest.raises(TypeError, match=r"^F: .*\(m, 3\)"):
        deform.write_mesh(str(tmp_path / "a.obj"), V, F.astype(float))
    with pytest.raises(ValueError, match=r"^V: expected shape \(n, 3\)"):
        deform.write_mesh(str(tmp_path / "a.obj"), V[:, :2], F)
    with pytest.raises(ValueError, match="out of range|outside"):
        deform.write_mesh(str(tmp_path / "a.obj"), V[:10], F)


# ---- the deformer ----


def test_precompute_reports_progress_and_the_sizes():
    V, F, _ = small_cylinder()
    deformer = deform.Deformer(V, F, deform.DeformerOptions(**OPTIONS))
    assert not deformer.ready
    stages = []
    summary = deformer.precompute(progress=lambda stage, fraction: stages.append((stage, fraction)))
    assert summary.ok() and deformer.ready
    assert summary.vertices == len(V) and deformer.vertex_count == len(V)
    assert summary.reduced_size == 3 * summary.linear_proxies + 12 * summary.patches + 9 * summary.rotational_proxies
    fractions = [f for _, f in stages]
    assert fractions == sorted(fractions) and fractions[-1] == 1.0 and len(stages) >= 3
    assert deformer.model_name == "arap"


def test_a_progress_callback_that_raises_aborts_precompute():
    V, F, _ = small_cylinder()
    deformer = deform.Deformer(V, F, deform.DeformerOptions(**OPTIONS))

    def stop(stage, fraction):
        if fraction > 0.1:
            raise KeyboardInterrupt("stopped by the test")

    with pytest.raises(KeyboardInterrupt, match="stopped by the test"):
        deformer.precompute(progress=stop)
    assert not deformer.ready


def test_a_progress_callback_calling_its_deformer_is_refused_not_deadlocked():
    V, F, _ = small_cylinder()
    deformer = deform.Deformer(V, F, deform.DeformerOptions(**OPTIONS))
    with pytest.raises(ValueError, match="its own precompute's progress"):
        deformer.precompute(progress=lambda stage, fraction: deformer.ready)
    assert not deformer.ready  # the lock is free again
    other = deform.Deformer(V, F, deform.DeformerOptions(**OPTIONS))
    assert deformer.precompute(progress=lambda stage, fraction: other.ready).ok()


def test_frame_writes_the_callers_array_without_a_copy():
    deformer, scenario = make_deformer()
    n = deformer.vertex_count
    out = np.full((n, 3), np.nan)
    address = out.__array_interface__["data"][0]
    result = deformer.frame(scenario.frames[0], out=out)
    assert result is out and out.__array_interface__["data"][0] == address
    assert np.all(np.isfinite(out))
    # A view into a larger buffer: the frame lands in the buffer's rows.
    buffer = np.zeros((n + 2, 3))
    view = buffer[1 : n + 1]
    deformer.frame(scenario.frames[1], out=view)
    assert np.array_equal(buffer[1 : n + 1], view) and np.all(buffer[0] == 0) and np.all(buffer[-1] == 0)
    assert np.any(buffer[1 : n + 1] != 0)


def test_frame_into_out_equals_a_new_array_bit_for_bit():
    a, scenario = make_deformer()
    b, _ = make_deformer()
    out = np.empty((a.vertex_count, 3))
    for targets in scenario.frames:
        a.frame(targets, out=out)
        fresh = b.frame(targets)
        assert np.array_equal(out, fresh)


def test_the_reconstruction_basis_gives_the_frame_through_the_normalization():
    deformer, scenario = make_deformer()
    V = deformer.frame(scenario.frames[-1])
    centre, scale = deformer.normalization
    rest = scenario.model.V
    lo, hi = rest.min(axis=0), rest.max(axis=0)
    assert np.allclose(centre, 0.5 * (lo + hi), rtol=0, atol=1e-12 * np.abs(rest).max())
    assert math.isclose(scale, np.linalg.norm(hi - lo), rel_tol=1e-12)
    B = deformer.reconstruction_basis.astype(np.float64)
    w = deformer.reduced_coordinates.astype(np.float64)
    mine = centre + scale * (B @ w).reshape(-1, 3) @ deformer.global_rotation.T
    # Float basis and coordinates: p products of size ~1 in the unit frame.
    assert np.abs(mine - V).max() <= 10 * w.size * FLOAT_EPS * scale


def test_a_double_basis_reconstructs_in_float64_to_double_round_off():
    deformer, scenario = make_deformer(double_basis=True)
    assert deformer.options.double_basis
    for targets in scenario.frames:
        V = deformer.frame(targets)
    B, w = deformer.reconstruction_basis, deformer.reduced_coordinates
    assert B.dtype == np.float64 and w.dtype == np.float64 and B.shape == (3 * deformer.vertex_count, w.size)
    centre, scale = deformer.normalization
    mine = centre + scale * (B @ w).reshape(-1, 3) @ deformer.global_rotation.T
    assert np.abs(mine - V).max() <= 10 * w.size * np.finfo(np.float64).eps * scale
    # The float basis's session: the same pose up to float round-off, not bit for bit.
    in_float, _ = make_deformer()
    for targets in scenario.frames:
        W = in_float.frame(targets)
    assert in_float.reconstruction_basis.dtype == np.float32
    assert 0 < np.abs(W - V).max() <= 1e-5 * scale


def test_frames_hold_the_handles_and_report_the_quality_readout():
    deformer, scenario = make_deformer()
    for targets in scenario.frames:
        V = deformer.frame(targets)
        summary = deformer.last_frame
        assert summary.ok()
        # The first frame after set_handles runs to the cold-start tolerance; the others `iterations` rounds.
        cap = deformer.options.cold_start_rounds if summary.cold_start else deformer.options.iterations
        assert summary.cold_start == (targets is scenario.frames[0])
        # (One more when the rounds ran again in the last global rotation: rotation_kept.)
        assert 1 <= summary.iterations == summary.rounds <= cap + summary.rotation_kept
        assert summary.fixed_point_residual >= 0 and math.isfinite(summary.fixed_point_residual)
        # Accelerated rounds by default: E′ of the pose and the safeguard's count.
        assert deformer.options.anderson_window > 0
        assert math.isfinite(summary.model_energy) and summary.model_energy >= 0
        assert 0 <= summary.rejected_steps <= summary.rounds
        assert summary.total_seconds >= summary.reconstruct_seconds > 0
        # Hard handles hold up to the float reconstruction: p products of size ~|V|.
        p = deformer.reduced_coordinates.shape[0]
        assert deformer.handle_residual(V) <= 10 * p * FLOAT_EPS * np.abs(V).max()
    assert deformer.rotations.shape == (9 * deformer.rotational_proxies,)
    plain, _ = make_deformer(anderson_window=0)
    plain.frame(scenario.frames[0])
    assert math.isnan(plain.last_frame.model_energy) and plain.last_frame.rejected_steps == 0
    R = deformer.global_rotation
    assert np.allclose(R.T @ R, np.eye(3), atol=1e-12) and np.isclose(np.linalg.det(R), 1.0)


def test_accelerated_rounds_report_the_model_energy():
    deformer, scenario = make_deformer(anderson_window=4, iterations=20)
    deformer.frame(scenario.frames[-1])
    summary = deformer.last_frame
    assert summary.ok() and math.isfinite(summary.model_energy) and summary.rejected_steps >= 0


def test_newton_options_are_exposed_and_checked():
    opts = deform.DeformerOptions(**OPTIONS)
    assert opts.second_order is True and opts.cold_start_rounds == 500 and opts.cold_start_tolerance == 1e-6
    deformer, scenario = make_deformer(second_order=False, cold_start_rounds=0)
    assert deformer.options.second_order is False and deformer.options.cold_start_rounds == 0
    deformer.frame(scenario.frames[-1])
    assert deformer.last_frame.second_order is False  # patch handles: rounds, never Newton steps
    assert deformer.last_frame.cold_start is False  # cold_start_rounds 0: the first frame runs like the others
    V, F, _ = small_cylinder()
    with pytest.raises(ValueError, match="cold_start_rounds must be in"):
        deform.Deformer(V, F, deform.DeformerOptions(**{**OPTIONS, "cold_start_rounds": -1})).precompute()


def test_the_first_frame_after_set_handles_runs_to_the_cold_start_tolerance():
    deformer, scenario = make_deformer(cold_start_tolerance=1e-8, cold_start_rounds=2000, iterations=8, tolerance=0.0)
    deformer.frame(scenario.frames[-1])
    first = deformer.last_frame
    deformer.frame(scenario.frames[-1])
    second = deformer.last_frame
    assert first.cold_start and not second.cold_start
    assert first.fixed_point_residual <= 1e-8 and first.iterations > deformer.options.iterations
    # (one more when the rounds ran again in the last global rotation)
    assert second.iterations <= deformer.options.iterations + second.rotation_kept


def test_frames_run_to_the_tolerance_within_the_time_budget():
    opts = deform.DeformerOptions()
    assert (opts.iterations, opts.tolerance, opts.time_budget) == (1000, 1e-6, 0.004)
    deformer, scenario = make_deformer(time_budget=1.0)  # a loaded machine can spend 4 ms on these frames
    for targets in scenario.frames:
        deformer.frame(targets)
        summary = deformer.last_frame
        assert summary.stop == qpreduce.RoundStop.Tolerance and summary.fixed_point_residual <= 1e-6
    # A budget the first round spends ends every frame after the cold start there.
    deformer.set_rounds(100000, 1e-14, time_budget=1e-9)
    deformer.frame(scenario.frames[-1])
    assert deformer.last_frame.stop == qpreduce.RoundStop.TimeBudget and deformer.last_frame.rounds == 1 + deformer.last_frame.rotation_kept
    deformer.set_rounds(8)  # the paper's fixed 8
    deformer.frame(scenario.frames[0])
    assert deformer.last_frame.stop == qpreduce.RoundStop.RoundLimit and deformer.last_frame.rounds == 8
    with pytest.raises(ValueError, match="time_budget"):
        deformer.set_rounds(8, 0.0, -1.0)
    V, F, _ = small_cylinder()
    with pytest.raises(ValueError, match="time_budget must be finite"):
        deform.Deformer(V, F, deform.DeformerOptions(**{**OPTIONS, "time_budget": float("nan")})).precompute()


def test_point_handles_from_vertex_indices_and_weighted_groups():
    V, F, _ = small_cylinder()
    deformer = deform.Deformer(V, F, deform.DeformerOptions(**OPTIONS))
    deformer.precompute()
    base = np.flatnonzero(V[:, 2] < 0.6)[::3]  # 6 of the 17 base vertices: the subspace can meet them
    top = np.flatnonzero(V[:, 2] > 11.4)
    weights = np.full(len(top), 1.0 / len(top))
    summary = deformer.set_handles(list(base) + [(top, weights)])
    assert summary.status == qpreduce.Status.Success, summary.message
    targets = np.vstack([V[base], V[top].mean(axis=0) + [1.0, 0.0, -0.5]])
    Vp = deformer.frame(np.ascontiguousarray(targets))
    assert np.allclose(Vp[top].mean(axis=0), targets[-1], atol=1e-4)
    assert deformer.handle_residual(Vp) < 1e-4


def test_handles_the_subspace_cannot_meet_are_met_softly_and_said_so():
    # Every base vertex as its own handle: 54 rows of rank 54 in the full space
    # but 30 in the subspace (10 linear proxies). By default they are met as
    # soft constraints (DeformerOptions.soften_unreachable_handles); the exact
    # least-squares form stays available.
    V, F, _ = small_cylinder()
    diagonal = np.linalg.norm(V.max(axis=0) - V.min(axis=0))
    base = np.flatnonzero(V[:, 2] < 0.6)
    top = np.flatnonzero(V[:, 2] > 11.4)
    handles = list(base) + [(top, np.full(len(top), 1.0 / len(top)))]
    targets = np.ascontiguousarray(np.vstack([V[base], V[top].mean(axis=0) + [1.0, 0.0, -0.5]]))
    for soften in (True, False):
        deformer = deform.Deformer(V, F, deform.DeformerOptions(**OPTIONS, soften_unreachable_handles=soften))
        deformer.precompute()
        with pytest.warns(qpreduce.QpreduceWarning, match="least-squares sense") as caught:
            summary = deformer.set_handles(handles)
        assert summary.status == qpreduce.Status.ConstraintsLeastSquares and summary.usable()
        assert summary.beyond_subspace  # the subspace's doing: naming the vertices at precompute makes it exact
        assert any("Name point-handle vertices at precompute" in str(w.message) for w in caught)
        if soften:
            assert "cannot meet these handles" in summary.message
            assert "rank 54 in the full space but 30 in the subspace" in summary.message
            assert "soft constraints (Eq. 18" in summary.message
        else:
            assert "least-squares sense" in summary.message
        for _ in range(3):
            with warnings.catch_warnings(record=True) as caught:  # a frame that ends off target says how far
                warnings.simplefilter("always")
                Vp = deformer.frame(targets)
            assert all("of the bounding-box diagonal from their targets" in str(w.message) for w in caught)
            assert np.isfinite(Vp).all()
            assert np.linalg.norm(Vp - V, axis=1).max() < 0.2 * diagonal  # the top moved 0.09 diagonals
            # soft: within 10⁻⁴ of the diagonal at δ = 10³ (measured 0.8·10⁻⁴); exact: to the float
            # reconstruction's round-off, a few ulps of the coordinates (|V| ≤ 12, one ulp 9.5·10⁻⁷;
            # measured 4–11·10⁻⁷ from frame to frame, 10⁻⁶ = 0.8·10⁻⁷ diagonals)
            assert deformer.handle_residual(Vp) < (1e-4 * diagonal if soften else 1e-6 * diagonal)
    # Merely dependent rows (a group over two handled vertices) keep the exact
    # form, soft or not: the subspace meets what the full space can.
    deformer = deform.Deformer(V, F, deform.DeformerOptions(**OPTIONS))
    deformer.precompute()
    few = list(base[::3])
    with pytest.warns(qpreduce.QpreduceWarning, match="one target"):  # dependent rows: the advice differs
        summary = deformer.set_handles(few + [(np.array(few[:2]), np.array([0.5, 0.5])), handles[-1]])
    assert summary.status == qpreduce.Status.ConstraintsLeastSquares
    assert "least-squares sense" in summary.message and "soft" not in summary.message
    assert not summary.beyond_subspace
    Vp = deformer.frame(np.ascontiguousarray(np.vstack([V[few], V[few[:2]].mean(axis=0), targets[-1]])))
    assert deformer.handle_residual(Vp) < 1e-6


def test_save_and_load_give_the_same_frames(tmp_path):
    deformer, scenario = make_deformer()
    path = str(tmp_path / "cylinder.qpr")
    deformer.save(path)
    loaded = deform.Deformer(scenario.model, deformer.options)
    assert loaded.load(path).ok() and loaded.ready
    loaded.set_handles(scenario.handles)
    for targets in scenario.frames:
        assert np.array_equal(deformer.frame(targets), loaded.frame(targets))
    # Another model: the cache is refused, naming the file.
    V, F, _ = small_cylinder(around=12)
    with pytest.raises(deform.IoError, match="cylinder.qpr"):
        deform.Deformer(V, F, deformer.options).load(path)
    with open(path, "r+b") as f:
        f.seek(200)
        f.write(b"\xff\xff\xff\xff")
    with pytest.raises(deform.IoError, match="cylinder.qpr"):
        deform.Deformer(scenario.model, deformer.options).load(path)


def test_conformal_model_with_gamma_keeps_scales_in_bounds():
    options = dict(model=deform.ModelKind.Conformal, conformal_bound=1.5,
                   energy=deform.EnergyParameters(alpha=0.1, beta=0.1, gamma=0.05))
    V, F, sel = small_cylinder()
    M = np.diag([0.6, 0.6, 0.6, 1.0])  # shrink the cap
    scenario = deform.sel_def_scenario(V, F, sel, M, frames=2)
    deformer = deform.Deformer(scenario.model, deform.DeformerOptions(**OPTIONS, **options))
    deformer.precompute()
    deformer.set_handles(scenario.handles)
    for targets in scenario.frames:
        deformer.frame(targets)
    assert deformer.model_name == "conformal"
    scales = deformer.cluster_scales
    assert np.all(scales >= 1 / 1.5 - 1e-12) and np.all(scales <= 1.5 + 1e-12)
    assert scales.min() < 0.99  # the shrunk cap shrinks some cluster


def test_tet_meshes_deform_too():
    V, T = deform.shapes.box_tets(1.0, 1.0, 4.0, 2, 2, 8)
    patch = np.full(len(V), -1)
    patch[V[:, 2] < 1e-9] = 0
    patch[V[:, 2] > 4 - 1e-9] = 1
    model = deform.Model(V, T, patch_of_vertex=patch, patch_types=[deform.PatchType.Fixed, deform.PatchType.Affine])
    deformer = deform.Deformer(model, deform.DeformerOptions(**OPTIONS))
    deformer.precompute()
    deformer.set_handles(patches=[1])
    move = np.hstack([np.eye(3), [[0.5], [0.0], [0.0]]])
    Vp = deformer.frame(patch_transforms=move[None])
    p = deformer.reduced_coordinates.shape[0]
    assert deformer.handle_residual(Vp) <= 10 * p * FLOAT_EPS * np.abs(Vp).max()
    assert np.allclose(Vp[patch == 1], V[patch == 1] + [0.5, 0, 0], atol=1e-4)
    assert np.allclose(deformer.patch_transform(1), move, atol=1e-6)


def test_local_global_reference_converges_and_its_energy_is_arap_energy():
    deformer, scenario = make_deformer()
    V, summary = deform.solve_local_global(scenario.model, scenario.handles, scenario.frames[-1],
                                           deform.ReferenceOptions(max_iterations=5000))
    assert summary.ok() and summary.converged and summary.handle_residual < 1e-9
    assert summary.energy == pytest.approx(deform.arap_energy(scenario.model, V), rel=1e-12)
    reduced = deformer.frame(scenario.frames[-1])
    # The reference minimises the classic energy from the same constraints.
    assert summary.energy <= deform.arap_energy(scenario.model, reduced) * (1 + 1e-9)


def test_json_scene(tmp_path):
    V, F, _ = small_cylinder()
    deform.write_mesh(str(tmp_path / "c.off"), V, F)
    base = [int(v) for v in np.flatnonzero(V[:, 2] < 0.6)]
    tip = int(np.argmax(V[:, 2]))
    (tmp_path / "scene.json").write_text(
        '{"mesh": "c.off", "energy": {"model": "conformal", "psi": 1.5, "gamma": 0.01},'
        '"proxies": {"linear": 10, "rotational": 8},'
        f'"patches": [{{"type": "fixed", "vertices": {base}}}],'
        f'"handles": [{{"name": "tip", "vertices": [{tip}], "targets": [[[0, 1, 12]], [[0, 2, 11]]]}}]}}')
    scenario = deform.read_scene(str(tmp_path / "scene.json"))
    assert len(scenario.frames) == 2
    options = scenario.options()
    assert options.model == deform.ModelKind.Conformal and options.energy.gamma == 0.01
    deformer = deform.Deformer(scenario.model, options)
    deformer.precompute()
    deformer.set_handles(scenario.handles, options=scenario.constraints)
    Vp = deformer.frame(scenario.frames[1])
    assert np.allclose(Vp[tip], [0, 2, 11], atol=1e-4)


def test_anim_scenario(tmp_path):
    V, F, _ = small_cylinder()
    base, tip = int(np.argmin(V[:, 2])), int(np.argmax(V[:, 2]))
    weights = np.zeros((2, len(V)))
    weights[0, base] = weights[1, tip] = 1.0
    targets = [[V[base], V[tip] + [0.5, 0, 0]], [V[base], V[tip] + [1.0, 0, -0.5]]]
    text = "2 2 %d 2 0 0 0\n" % len(V)
    text += "\n".join(" ".join(repr(w) for w in row) for row in weights) + "\n"
    text += "\n".join(" ".join(repr(float(x)) for p in frame for x in p) for frame in targets) + "\n"
    (tmp_path / "c.anim").write_text(text)
    scenario = deform.anim_scenario(V, F, str(tmp_path / "c.anim"))
    assert len(scenario.handles.points) == 2 and len(scenario.frames) == 2
    assert np.allclose(scenario.frames[1].points, targets[1])
    with pytest.raises(deform.IoError, match="c.anim"):
        deform.anim_scenario(V[:100], F[:10], str(tmp_path / "c.anim"))


# ---- errors: each bad input raises the named exception ----


@pytest.fixture(scope="module")
def ready():
    return make_deformer()


def expect(exception, pattern, call):
    with pytest.raises(exception, match=pattern):
        call()


def test_bad_meshes_name_the_argument_and_shape():
    V, F, _ = small_cylinder()
    bad_V = V.copy()
    bad_V[3, 1] = np.nan
    expect(TypeError, r"^V: .*\(n, 3\)", lambda: deform.Deformer(V.astype(complex), F))
    expect(TypeError, r"^V: expected a numpy.ndarray", lambda: deform.Deformer(V.tolist(), F))
    expect(ValueError, r"^V: expected shape \(n, 3\), got \(322, 2\)", lambda: deform.Deformer(V[:, :2], F))
    expect(ValueError, r"^V: contains NaN", lambda: deform.Deformer(bad_V, F))
    expect(TypeError, r"^elements: .*integers", lambda: deform.Deformer(V, F.astype(float)))
    expect(ValueError, r"^elements: expected shape \(m, 3\) or \(m, 4\)", lambda: deform.Deformer(V, F[:, :2]))
    expect(ValueError, r"^clusters: expected shape \(n,\) = \(322,\)",
           lambda: deform.Deformer(V, F, clusters=np.zeros(5, dtype=int)))
    expect(TypeError, r"^options: expected DeformerOptions", lambda: deform.Deformer(V, F, options=3))
    expect(TypeError, r"^patch_types: expected a list of qpreduce.deform.PatchType",
           lambda: deform.Model(V, F, patch_of_vertex=np.zeros(len(V), dtype=int), patch_types=["fixed"]))
    expect(ValueError, "", lambda: deform.Deformer(V, F + len(V)).precompute())  # indices out of range
    expect(ValueError, "DeformerOptions", lambda: deform.Deformer(V, F, deform.DeformerOptions(iterations=0)).precompute())
    expect(TypeError, r"^progress: expected a callable", lambda: deform.Deformer(V, F).precompute(progress=1))


def test_calls_out_of_order_raise_value_error():
    V, F, _ = small_cylinder()
    deformer = deform.Deformer(V, F)
    expect(ValueError, "precompute", lambda: deformer.frame())
    expect(ValueError, "precompute", lambda: deformer.set_handles([0]))
    expect(ValueError, "precompute", lambda: deformer.save("/tmp/never.qpr"))


def test_bad_frame_arguments(ready):
    deformer, scenario = ready
    n = deformer.vertex_count
    with pytest.warns(qpreduce.QpreduceWarning, match="dependent rows"):  # 0 and 5 are in a fixed patch
        deformer.set_handles(deform.Handles(points=[0, 5], patches=[1]))
    good_pt = np.eye(4)[None, :3]
    good = np.zeros((2, 3))
    strided = np.zeros((2, 6))[:, ::2]
    nan = good.copy()
    nan[1, 2] = np.nan
    expect(TypeError, r"^targets: expected a numpy.ndarray of float64 with shape \(h, 3\) = \(2, 3\), got dtype float32",
           lambda: deformer.frame(good.astype(np.float32)))
    expect(ValueError, r"^targets: .*\(h, 3\) = \(2, 3\), got \(3, 3\)", lambda: deformer.frame(np.zeros((3, 3))))
    expect(ValueError, r"^targets: expected a C-contiguous array", lambda: deformer.frame(strided))
    expect(ValueError, r"^targets: contains NaN", lambda: deformer.frame(nan))
    expect(TypeError, r"^targets: .*got list", lambda: deformer.frame([[0, 0, 0], [0, 0, 0]]))
    expect(TypeError, r"^targets: .*got None", lambda: deformer.frame())
    expect(TypeError, r"^out: .*\(n, 3\) = \(322, 3\), got dtype float32",
           lambda: deformer.frame(good, patch_transforms=good_pt, out=np.zeros((n, 3), np.float32)))
    expect(ValueError, r"^out: .*got \(321, 3\)", lambda: deformer.frame(good, patch_transforms=good_pt, out=np.zeros((n - 1, 3))))
    expect(ValueError, r"^out: expected a C-contiguous array", lambda: deformer.frame(good, patch_transforms=good_pt, out=np.zeros((n, 3), order="F")))
    read_only = np.zeros((n, 3))
    read_only.flags.writeable = False
    expect(ValueError, r"^out: the array is read-only", lambda: deformer.frame(good, patch_transforms=good_pt, out=read_only))
    expect(ValueError, "", lambda: deformer.set_handles([n]))  # vertex out of range
    expect(TypeError, r"^points\[0\]: expected a vertex index", lambda: deformer.set_handles(["a"]))
    expect(TypeError, r"^handles: expected a Handles", lambda: deformer.set_handles(3))
    expect(ValueError, r"^p: expected a patch index", lambda: deformer.patch_transform(99))
    deformer.set_handles(scenario.handles)
    expect(TypeError, r"^patch_transforms: .*\(s, 3, 4\) = \(1, 3, 4\), got None", lambda: deformer.frame(np.zeros((0, 3))))
    expect(ValueError, r"^patch_transforms: .*got \(1, 4, 4\)",
           lambda: deformer.frame(np.zeros((0, 3)), patch_transforms=np.zeros((1, 4, 4))))
    expect(ValueError, r"^patch_transforms: contains NaN",
           lambda: deformer.frame(np.zeros((0, 3)), patch_transforms=np.full((1, 3, 4), np.nan)))


def test_failed_numerical_steps_raise_numerical_error(ready):
    deformer, _ = ready
    # No handle on a model without fixed patches: rigid motions are free.
    V, F, _ = small_cylinder()
    free = deform.Deformer(V, F, deform.DeformerOptions(**OPTIONS))
    free.precompute()
    with pytest.raises(qpreduce.NumericalError) as raised:
        free.set_handles([])
    assert raised.value.status == qpreduce.Status.Unbounded
    assert "not strictly convex" in raised.value.message
    assert raised.value.summary.status == qpreduce.Status.Unbounded


@pytest.mark.skipif(not deform.has_ceres_reference(), reason="qpreduce built without Ceres")
def test_ceres_and_local_global_references_agree():
    _, scenario = make_deformer(frames=1)
    targets = scenario.frames[-1]
    V_lg, lg = deform.solve_local_global(scenario.model, scenario.handles, targets,
                                         deform.ReferenceOptions(max_iterations=20000))
    V_c, ceres = deform.solve_ceres_reference(scenario.model, scenario.handles, targets,
                                              deform.ReferenceOptions(max_iterations=500), initial=V_lg)
    assert lg.converged and ceres.ok()
    # Both minimise the classic energy from the same constraints; Ceres starts
    # at the local-global pose and may only go down.
    assert ceres.energy <= lg.energy * (1 + 1e-9)
    assert ceres.energy == pytest.approx(lg.energy, rel=1e-6)
    assert ceres.handle_residual < 1e-9


def test_every_public_function_has_a_docstring_beyond_its_signature():
    import inspect

    missing = []
    for name in dir(deform):
        obj = getattr(deform, name)
        if name.startswith("_") or not callable(obj):
            continue
        members = [(f"{name}.{m}", getattr(obj, m)) for m in dir(obj) if not m.startswith("_") or m == "__init__"] \
            if inspect.isclass(obj) else [(name, obj)]
        for full, member in members:
            lines = [line for line in (getattr(member, "__doc__", None) or "").splitlines() if line.strip()]
            own_init = full.endswith("__init__") and name in ("Model", "Deformer", "PointHandle", "Handles",
                                                                 "HandleTargets", "DeformerOptions")
            if (own_init or not full.endswith("__init__")) and callable(member) and not inspect.isclass(member) \
                    and len(lines) < 2:
                missing.append(full)
    assert not missing, missing


def test_a_failed_reference_solve_raises_numerical_error():
    _, scenario = make_deformer(frames=1)
    # The handle patch left free: its flat cap does not determine its affine
    # map (the normal column), so the global step is singular.
    with pytest.raises(qpreduce.NumericalError) as raised:
        deform.solve_local_global(scenario.model, deform.Handles(), deform.HandleTargets())
    assert raised.value.status == qpreduce.Status.NumericalFailure
    assert raised.value.summary.status == raised.value.status and raised.value.message
