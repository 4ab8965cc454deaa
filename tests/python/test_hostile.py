"""Hostile inputs cannot crash the interpreter (docs/robustness.md, "Python").

Each group of cases runs in a subprocess, so that a crash (SIGSEGV, SIGABRT)
fails the test instead of ending the pytest run: the child prints one line
per case that raised the expected exception with the expected words, and the
test requires every line and exit code 0.
"""

import os
import subprocess
import sys
import textwrap

import pytest

HERE = os.path.dirname(os.path.abspath(__file__))

PRELUDE = textwrap.dedent("""
    import re, sys
    import numpy as np
    import scipy.sparse
    import qpreduce
    from qpreduce import deform
    sys.path.insert(0, {here!r})
    from conftest import RandomProblem

    def expect(name, error, words, call):
        try:
            call()
        except error as e:
            for w in words:
                if w not in str(e):
                    print("WRONG", name, repr(str(e)[:300]), "lacks", repr(w))
                    return
            print("OK", name)
            return
        except Exception as e:
            print("WRONG", name, type(e).__name__, str(e)[:300])
            return
        print("WRONG", name, "no exception")
""").format(here=HERE)


def run_cases(body, names):
    code = PRELUDE + textwrap.dedent(body)
    p = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=120,
                       env=dict(os.environ, OMP_NUM_THREADS="1"))
    said = p.stdout + p.stderr
    assert p.returncode == 0, f"the interpreter ended with {p.returncode}:\n{said[-3000:]}"
    wrong = [line for line in p.stdout.splitlines() if line.startswith("WRONG")]
    assert not wrong, "\n".join(wrong)
    missing = [n for n in names if f"OK {n}" not in p.stdout.splitlines()]
    assert not missing, f"cases that did not report: {missing}\n{said[-3000:]}"


SPARSE = [f"{where} {kind}" for where in ("precompute H", "set_constraints A")
          for kind in ("csr index out of range", "csc negative index", "csr indptr decreasing",
                       "csc data too short", "coo row out of range", "coo col negative")]


def test_corrupted_sparse_matrices_are_refused_naming_the_argument():
    run_cases("""
        problem = RandomProblem(seed=5)

        def corrupt(matrix, kind):
            if kind == "csr index out of range":
                m = scipy.sparse.csr_matrix(matrix, copy=True); m.indices[3] = m.shape[1] + 7
            elif kind == "csc negative index":
                m = scipy.sparse.csc_matrix(matrix, copy=True); m.indices[2] = -4
            elif kind == "csr indptr decreasing":
                m = scipy.sparse.csr_matrix(matrix, copy=True); m.indptr[2] = m.indptr[3] + 5
            elif kind == "csc data too short":
                m = scipy.sparse.csc_matrix(matrix, copy=True); m.data = m.data[:-3]
            elif kind == "coo row out of range":
                m = scipy.sparse.coo_matrix(matrix, copy=True); m.row[1] = m.shape[0] + 2
            else:
                m = scipy.sparse.coo_matrix(matrix, copy=True); m.col[0] = -1
            return m

        for kind in ["csr index out of range", "csc negative index", "csr indptr decreasing",
                     "csc data too short", "coo row out of range", "coo col negative"]:
            solver = qpreduce.SubspaceSolver()
            expect("precompute H " + kind, ValueError, ["H: not a valid"],
                   lambda: solver.precompute(corrupt(problem.H, kind), problem.C, problem.D))
            ready = qpreduce.SubspaceSolver()
            assert ready.precompute(problem.H, problem.C, problem.D).ok()
            expect("set_constraints A " + kind, ValueError, ["A: not a valid"],
                   lambda: ready.set_constraints(corrupt(problem.A, kind)))
    """, SPARSE)


KINDS = ["csr index out of range", "csc negative index", "csr indptr decreasing", "csc data too short",
         "coo row out of range", "coo col negative", "lil col out of range", "lil row lengths differ",
         "bsr index out of range", "dok key out of range"]
# Every binding argument that takes a matrix, sparse (sparse_arg) or dense (dense_arg).
ARGUMENTS = ["SubspaceSolver.precompute C", "SubspaceSolver32.precompute D", "restore N",
             "set_constraints_in_design A_c", "solve_full A", "factor_psd H", "PsdFactor.whiten M",
             "whiten_design C", "companion_demand A", "h_distance H", "TheoremChecker.precompute H",
             "TheoremChecker.check A", "check_theorem A", "HandleTargets points", "sel_def_scenario def"]


def test_every_matrix_argument_refuses_every_corruption():
    run_cases("""
        problem = RandomProblem(seed=5)
        H, C, D, A = problem.H, problem.C, problem.D, problem.A
        solver = qpreduce.SubspaceSolver()
        assert solver.precompute(H, C, D).ok()
        factor, _ = qpreduce.factor_psd(H)
        checker = qpreduce.TheoremChecker()
        checker.precompute(H, C, D)
        V, F = deform.shapes.capped_cylinder(1.0, 4.0, 12, 6)
        sel = np.ones(len(V), dtype=np.int32)
        sel[V[:, 2] < 0.3] = 0
        sel[V[:, 2] > 3.7] = 2
        calls = {
            "SubspaceSolver.precompute C": (C, lambda m: qpreduce.SubspaceSolver().precompute(H, m, D)),
            "SubspaceSolver32.precompute D": (D, lambda m: qpreduce.SubspaceSolver32().precompute(H, C, m)),
            "restore N": (solver.subspace.N, lambda m: qpreduce.SubspaceSolver().restore(
                m, solver.subspace.UD, solver.reduced_hessian, solver.reduced_linear_map)),
            "set_constraints_in_design A_c": (problem.A_c, lambda m: solver.set_constraints_in_design(m)),
            "solve_full A": (A, lambda m: qpreduce.solve_full(H, m, problem.b, problem.q)),
            "factor_psd H": (H, lambda m: qpreduce.factor_psd(m)),
            "PsdFactor.whiten M": (C, lambda m: factor.whiten(m)),
            "whiten_design C": (C, lambda m: qpreduce.whiten_design(factor, m, D)),
            "companion_demand A": (A, lambda m: qpreduce.companion_demand(factor, m, problem.b, problem.q,
                                                                           np.zeros(60))),
            "h_distance H": (H, lambda m: qpreduce.h_distance(m, np.zeros(60), np.ones(60))),
            "TheoremChecker.precompute H": (H, lambda m: qpreduce.TheoremChecker().precompute(m, C, D)),
            "TheoremChecker.check A": (A, lambda m: checker.check(m, problem.b, problem.q)),
            "check_theorem A": (A, lambda m: qpreduce.check_theorem(H, C, D, m, problem.b, problem.q)),
            "HandleTargets points": (np.ones((6, 3)), lambda m: deform.HandleTargets(m)),
            "sel_def_scenario def": (np.eye(4), lambda m: deform.sel_def_scenario(V, F, sel, m)),
        }

        def corrupt(matrix, kind):
            dense = matrix.toarray() if scipy.sparse.issparse(matrix) else np.asarray(matrix)
            dense = dense + 1.0  # every entry stored
            rows, cols = dense.shape
            if kind == "csr index out of range":
                m = scipy.sparse.csr_matrix(dense); m.indices[1] = cols + 7
            elif kind == "csc negative index":
                m = scipy.sparse.csc_matrix(dense); m.indices[0] = -4
            elif kind == "csr indptr decreasing":
                m = scipy.sparse.csr_matrix(dense); m.indptr[1] = m.indptr[2] + 3
            elif kind == "csc data too short":
                m = scipy.sparse.csc_matrix(dense); m.data = m.data[:-1]
            elif kind == "coo row out of range":
                m = scipy.sparse.coo_matrix(dense); m.row[1] = rows + 2
            elif kind == "coo col negative":
                m = scipy.sparse.coo_matrix(dense); m.col[0] = -1
            elif kind == "lil col out of range":
                m = scipy.sparse.lil_matrix(dense); m.rows[0] = [0, 10**6]; m.data[0] = [1.0, 2.0]
            elif kind == "lil row lengths differ":
                m = scipy.sparse.lil_matrix(dense); m.rows[0] = [0]; m.data[0] = [1.0] * 9
            elif kind == "bsr index out of range":
                m = scipy.sparse.bsr_matrix(dense, blocksize=(1, 1)); m.indices[0] = 10**6
            else:
                m = scipy.sparse.dok_matrix(dense); dict.__setitem__(m, (rows + 5, 0), 1.0)
            return m

        for label, (matrix, call) in calls.items():
            argument = label.split()[-1]
            for kind in KINDS:
                expect(label + " " + kind, ValueError, [argument + ": not a valid " + kind.split()[0].upper()],
                       lambda: call(corrupt(matrix, kind)))
            m = scipy.sparse.csr_matrix(np.asarray(matrix.toarray() if scipy.sparse.issparse(matrix) else matrix))
            m.indices = m.indices.astype(float)
            expect(label + " float indices", TypeError, [argument + ": not a valid CSR matrix",
                                                        "indices must hold integers"], lambda: call(m))

        # A valid matrix with unused trailing entries and int64 indices is read, not changed.
        m = scipy.sparse.csr_matrix(C)
        m.indices = np.concatenate([m.indices, [0]]).astype(np.int64)
        m.data = np.concatenate([m.data, [7.0]])
        before = (m.indices.copy(), m.data.copy(), m.indptr.copy())
        assert qpreduce.SubspaceSolver().precompute(H, m, D).ok()
        assert all(np.array_equal(x, y) and x.dtype == y.dtype for x, y in zip(before, (m.indices, m.data, m.indptr)))
        print("OK the caller's matrix is not changed")
        # Duplicates are summed, as SciPy does; unsorted indices are sorted.
        dup = scipy.sparse.coo_matrix((np.r_[problem.A[:, 0], problem.A[:, 0]],
                                       (np.r_[np.arange(60), np.arange(60)], np.zeros(120, dtype=int))), shape=(60, 1))
        solver.set_constraints(dup)
        summed = solver.reduced_constraints
        solver.set_constraints(2 * problem.A[:, :1])
        assert summed.shape == (1, solver.p) and np.array_equal(summed, solver.reduced_constraints)
        print("OK duplicates summed")
    """.replace("KINDS", repr(KINDS)),
        [f"{label} {kind}" for label in ARGUMENTS for kind in KINDS + ["float indices"]]
        + ["the caller's matrix is not changed", "duplicates summed"])


def test_out_overlapping_an_input_is_refused():
    run_cases("""
        problem = RandomProblem(seed=5)
        solver = qpreduce.SubspaceSolver()
        assert solver.precompute(problem.H, problem.C, problem.D).ok()
        assert solver.set_constraints(problem.A).ok()
        p, m, k, n = solver.p, solver.m, solver.k, solver.n
        buf = np.zeros(max(p, n) + k + m + 8)
        b = np.linspace(0.0, 1.0, m)
        buf[:k] = 1.0
        expect("solve_in_D out over Y", ValueError, ["out: shares memory with Y"],
               lambda: solver.solve_in_D(b, buf[:k], out=buf[:p]))
        buf2 = np.zeros(p + m)
        expect("solve out over b", ValueError, ["out: shares memory with b"],
               lambda: solver.solve(buf2[p - 1:p - 1 + m], np.zeros(p), out=buf2[:p]))
        q_r = np.zeros(p)
        expect("solve out is q_r", ValueError, ["out: shares memory with q_r"],
               lambda: solver.solve(b, q_r, out=q_r))
        buf3 = np.zeros(n + p)
        expect("reconstruct out over w", ValueError, ["out: shares memory with w"],
               lambda: solver.reconstruct(buf3[n - 2:n - 2 + p], out=buf3[:n]))
        buf4 = np.zeros(n + p)
        expect("reduce_linear_term out over q", ValueError, ["out: shares memory with q"],
               lambda: solver.reduce_linear_term(buf4[:n], out=buf4[n - 1:n - 1 + p]))
        # Disjoint slices of one buffer are fine.
        whole = np.zeros(p + k)
        whole[p:] = 1.0
        solver.solve_in_D(b, whole[p:], out=whole[:p])
        print("OK disjoint slices run")
    """, ["solve_in_D out over Y", "solve out over b", "solve out is q_r", "reconstruct out over w",
          "reduce_linear_term out over q", "disjoint slices run"])


def test_handle_residual_and_failed_handle_sets_never_read_out_of_bounds():
    run_cases("""
        V, F = deform.shapes.capped_cylinder(1.0, 4.0, 12, 6)
        sel = np.ones(len(V), dtype=np.int32)
        sel[V[:, 2] < 0.3] = 0
        sel[V[:, 2] > 3.7] = 2
        M = np.eye(4); M[:3, 3] = [0.0, 0.5, 0.0]
        sc = deform.sel_def_scenario(V, F, sel, M, frames=2)
        one_target = deform.HandleTargets(np.zeros((1, 3)))
        expect("free handle_residual vertex out of range", ValueError, ["vertex 1000000 outside [0,"],
               lambda: deform.handle_residual(sc.model, deform.Handles([10**6]), one_target, sc.model.V))
        expect("free handle_residual short weights", ValueError, ["1 weights for 3 vertices"],
               lambda: deform.handle_residual(sc.model, deform.Handles([deform.PointHandle([0, 1, 2], [1.0])]),
                                              one_target, sc.model.V))
        expect("free handle_residual fewer target rows", ValueError, ["targets for 1 points"],
               lambda: deform.handle_residual(sc.model, deform.Handles([0, 1]), one_target, sc.model.V))
        d = deform.Deformer(sc.model, deform.DeformerOptions(rotational_proxies=6, linear_proxies=8))
        d.precompute()
        d.set_handles(sc.handles, options=sc.constraints)
        expect("Deformer.handle_residual before a frame", ValueError, ["no frame yet"],
               lambda: d.handle_residual(sc.model.V))
        V1 = d.frame(sc.frames[-1])
        assert d.handle_residual(V1) < 1e-3
        print("OK a frame's residual")
        expect("a group with every weight 0", ValueError, ["every weight is 0"],
               lambda: d.set_handles([([0, 1], [0.0, 0.0])]))
        expect("frame after a refused handle set", ValueError, ["the last set_handles failed"],
               lambda: d.frame(np.zeros((1, 3))))
        assert not d.ready
        print("OK not ready after a refused set")
        expect("set_handles([]) fails", qpreduce.NumericalError, ["not strictly convex"],
               lambda: d.set_handles([]))
        assert not d.ready
        expect("frame after a failed handle set", ValueError, ["the last set_handles failed"],
               lambda: d.frame(np.zeros((0, 3))))
        # A vertex pinned twice: the CLI's words.
        mid = [int(v) for v in np.flatnonzero(np.abs(V[:, 2] - 2.0) < 0.5)[:2]]
        patches = list(sc.handles.patches)
        transforms = list(sc.frames[-1].patch_transforms)
        d.set_handles([mid[0], mid[1], mid[0]], patches=patches)
        pins = np.array([V[mid[0]], V[mid[1]], V[mid[0]] + [0.0, 0.3, 0.0]])
        expect("a vertex held at two places", ValueError,
               ["Deformer.frame: vertex %d is held at two places by point handles 0 and 2" % mid[0],
                "bounding-box diagonals apart"],
               lambda: d.frame(pins, patch_transforms=np.array(transforms)))
        d.frame(np.array([V[mid[0]], V[mid[1]], V[mid[0]]]), patch_transforms=np.array(transforms))
        print("OK the same place twice runs")
        d.set_handles(sc.handles, options=sc.constraints)
        assert d.ready
        V2 = d.frame(sc.frames[-1])
        assert d.handle_residual(V2) < 1e-3
        print("OK a good set makes it ready again")
    """, ["free handle_residual vertex out of range", "free handle_residual short weights",
          "free handle_residual fewer target rows", "Deformer.handle_residual before a frame", "a frame's residual",
          "a group with every weight 0", "frame after a refused handle set", "not ready after a refused set",
          "set_handles([]) fails", "frame after a failed handle set", "a vertex held at two places",
          "the same place twice runs", "a good set makes it ready again"])


def test_sizes_empty_matrices_and_replaced_scenario_parts_are_refused():
    run_cases("""
        expect("capped_cylinder beyond 32-bit indices", ValueError,
               ["capped_cylinder:", "beyond the 32-bit indices"],
               lambda: deform.shapes.capped_cylinder(1.0, 4.0, 2**40, 2**40))
        expect("box_tets beyond 32-bit indices", ValueError, ["box_tets:", "beyond the 32-bit indices"],
               lambda: deform.shapes.box_tets(1.0, 1.0, 1.0, 2**22, 2**22, 2**22))
        empty = scipy.sparse.csc_matrix((0, 0))
        expect("factor_psd of an empty H", ValueError, ["factor_psd: H is empty"], lambda: qpreduce.factor_psd(empty))
        expect("TheoremChecker of an empty H", ValueError, ["H is empty"],
               lambda: qpreduce.TheoremChecker().precompute(empty, empty, None))

        V, F = deform.shapes.capped_cylinder(1.0, 4.0, 12, 6)
        sel = np.where(V[:, 2] < 0.3, 0, np.where(V[:, 2] > 3.7, 2, 1)).astype(np.int32)
        sc = deform.sel_def_scenario(V, F, sel, np.eye(4))
        sc.handles = deform.Handles([10**6])
        expect("anchored_vertices with a handle out of range", ValueError, ["vertex 1000000 outside [0, 74)"],
               lambda: deform.anchored_vertices(sc))
        sc = deform.sel_def_scenario(V, F, sel, np.eye(4))
        sc.model = deform.Model(V, F, patch_of_vertex=np.full(len(V), 4), patch_types=[deform.PatchType.Fixed])
        expect("anchored_vertices with a patch label out of range", ValueError,
               ["anchored_vertices: vertex 0 has patch 4 outside [-1, 1)"], lambda: deform.anchored_vertices(sc))

        d = deform.Deformer(V, F, deform.DeformerOptions(rotational_proxies=6, linear_proxies=8))
        d.precompute()
        expect("a vertex index beyond 64 bits", ValueError, ["points[0]: vertex index", "is out of range"],
               lambda: d.set_handles([2**70]))
        expect("a patch index beyond 64 bits", TypeError, ["patches: expected integers"],
               lambda: d.set_handles([0], patches=[10**30]))
        expect("a PointHandle item with short weights", ValueError, ["point handle 0: 1 weights for 2 vertices"],
               lambda: d.set_handles([deform.PointHandle([0, 1], [0.5])]))
    """, ["capped_cylinder beyond 32-bit indices", "box_tets beyond 32-bit indices", "factor_psd of an empty H",
          "TheoremChecker of an empty H", "anchored_vertices with a handle out of range",
          "anchored_vertices with a patch label out of range", "a vertex index beyond 64 bits",
          "a patch index beyond 64 bits", "a PointHandle item with short weights"])


def test_a_new_precompute_starts_without_handles_and_a_failed_one_keeps_them():
    run_cases("""
        V, F = deform.shapes.capped_cylinder(1.0, 4.0, 12, 6)
        d = deform.Deformer(V, F, deform.DeformerOptions(rotational_proxies=6, linear_proxies=8))
        d.precompute()
        expect("frame before any set_handles", ValueError, ["Deformer.frame: call set_handles first"],
               lambda: d.frame(np.zeros((0, 3))))
        pins = np.ascontiguousarray(V[[0, 40, 70]])
        d.set_handles([0, 40, 70])
        d.frame(pins)

        def abort(stage, fraction):
            raise KeyError("stop")
        expect("a precompute its progress aborts", KeyError, ["stop"], lambda: d.precompute(progress=abort))
        assert d.ready and len(d.handles.points) == 3 and d.frame(pins).shape == V.shape
        print("OK the aborted precompute kept the handles")
        d.precompute()
        assert d.ready and len(d.handles.points) == 0
        expect("frame after a new precompute", ValueError, ["Deformer.frame: call set_handles first"],
               lambda: d.frame(pins))
        d.set_handles([0, 40, 70])
        assert d.frame(pins).shape == V.shape
        print("OK a new set after the new precompute")
        # Targets the CLI refuses as overflowing (scenario check) are refused with its words.
        expect("a target beyond 1e30", ValueError,
               ["Deformer::frame: a point handle's target reaches",
                "bounding-box diagonals from the rest pose's centre: handle targets beyond 1e+30 diagonals overflow "
                "in the energy"], lambda: d.frame(np.full((3, 3), 1e300)))
        assert d.frame(pins).shape == V.shape
        print("OK frames run after the refused targets")
    """, ["frame before any set_handles", "a precompute its progress aborts", "the aborted precompute kept the handles",
          "frame after a new precompute", "a new set after the new precompute", "a target beyond 1e30",
          "frames run after the refused targets"])
