"""Deform the Botsch–Sorkine cactus with reduced ARAP, its handle moved along a path.

The cactus (../shared/data/meshes/botsch-sorkine/cactus.off with cactus.sel:
0 fixed, 1 free, 2 handle) is precomputed once; the handle region is an
affine patch whose transform follows a path: the .def pose reached along a
circular arc (rotation by the .def's axis–angle times t, translation along
the arc). Each frame is written as OBJ; when the path ends, the last pose is
refined to converged full-space ARAP (deform.Refiner), and a matplotlib
figure shows the rest pose, a few frames and the refined one. Without ../shared the built-in capped cylinder of
`qpr demo` is bent instead (--builtin forces it).

    PYTHONPATH=build/python python3 python/examples/deform_cactus.py [--frames 24] [--out cactus-frames]
"""

import argparse
import math
import os
import time

import matplotlib

matplotlib.use("Agg")  # files only, no display
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402

from qpreduce import deform  # noqa: E402

ROOT = os.path.dirname(os.path.dirname(os.path.dirname(os.path.abspath(__file__))))
# The shared test data beside the checkout, or where $QPREDUCE_SHARED_DATA says.
SHARED = os.path.join(os.environ.get("QPREDUCE_SHARED_DATA", os.path.join(os.path.dirname(ROOT), "shared", "data")),
                      "meshes", "botsch-sorkine")


def axis_angle(R):
    """(unit axis, angle) of a rotation matrix."""
    angle = math.acos(max(-1.0, min(1.0, (np.trace(R) - 1) / 2)))
    axis = np.array([R[2, 1] - R[1, 2], R[0, 2] - R[2, 0], R[1, 0] - R[0, 1]])
    norm = np.linalg.norm(axis)
    return (axis / norm if norm > 0 else np.array([0.0, 0.0, 1.0])), angle


def rotation(axis, angle):
    K = np.array([[0, -axis[2], axis[1]], [axis[2], 0, -axis[0]], [-axis[1], axis[0], 0]])
    return np.eye(3) + math.sin(angle) * K + (1 - math.cos(angle)) * K @ K


def load_model(builtin, around, rings):
    """(V, F, sel roles, 4×4 final handle map, name)."""
    if not builtin and os.path.exists(os.path.join(SHARED, "cactus.off")):
        V, F = deform.read_mesh(os.path.join(SHARED, "cactus.off"))
        sel = deform.read_sel(os.path.join(SHARED, "cactus.sel"))
        return V, F, sel, deform.read_def(os.path.join(SHARED, "cactus.def")), "cactus"
    if not builtin:
        print(f"{SHARED} not found: bending the built-in cylinder instead")
    V, F = deform.shapes.capped_cylinder(1.0, 12.0, around, rings)
    sel = np.ones(len(V), dtype=np.int32)
    sel[V[:, 2] < 0.6] = 0
    sel[V[:, 2] > 11.4] = 2
    M = np.eye(4)
    M[:3, :3] = rotation(np.array([1.0, 0.0, 0.0]), math.pi / 2)
    M[:3, 3] = np.array([0.0, -12 * 2 / math.pi, 12 * 2 / math.pi]) - M[:3, :3] @ np.array([0.0, 0.0, 12.0])
    return V, F, sel, M, "cylinder"


def path_transforms(V, sel, M, frames):
    """One 3×4 [A | t] per frame: the handle's centre moves along a circular
    arc (through its rest centre, bulging sideways) to where M puts it, while
    it turns by t·angle about M's axis."""
    centre = V[sel == 2].mean(axis=0)
    axis, angle = axis_angle(M[:3, :3])
    end = M[:3, :3] @ centre + M[:3, 3]
    side = np.cross(axis, end - centre)
    side = side / np.linalg.norm(side) * 0.25 * np.linalg.norm(end - centre) if np.linalg.norm(side) > 0 else 0
    out = []
    for f in range(1, frames + 1):
        t = f / frames
        R = rotation(axis, t * angle)
        target = centre + t * (end - centre) + math.sin(math.pi * t) * side
        out.append(np.hstack([R, (target - R @ centre)[:, None]]))
    return np.array(out)


def figure(V, F, poses, path, title):
    fig = plt.figure(figsize=(4 * len(poses), 4.5))
    lo, hi = np.min([P.min(axis=0) for _, P in poses], axis=0), np.max([P.max(axis=0) for _, P in poses], axis=0)
    for i, (label, P) in enumerate(poses):
        ax = fig.add_subplot(1, len(poses), i + 1, projection="3d")
        ax.plot_trisurf(P[:, 0], P[:, 1], P[:, 2], triangles=F, color="#8fb996", edgecolor="none", shade=True)
        ax.set_xlim(lo[0], hi[0])
        ax.set_ylim(lo[1], hi[1])
        ax.set_zlim(lo[2], hi[2])
        ax.set_box_aspect(hi - lo)
        ax.set_axis_off()
        ax.set_title(label)
    fig.suptitle(title)
    fig.tight_layout()
    fig.savefig(path, dpi=90)
    plt.close(fig)


def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--frames", type=int, default=24)
    parser.add_argument("--out", default="cactus-frames", help="folder for the OBJ frames and the figure")
    parser.add_argument("--builtin", action="store_true", help="the built-in cylinder even when ../shared exists")
    parser.add_argument("--around", type=int, default=60, help="built-in cylinder: vertices per ring")
    parser.add_argument("--rings", type=int, default=80, help="built-in cylinder: rings")
    parser.add_argument("--rotational-proxies", type=int, default=27)
    parser.add_argument("--linear-proxies", type=int, default=33)
    args = parser.parse_args(argv)

    V, F, sel, M, name = load_model(args.builtin, args.around, args.rings)
    scenario = deform.sel_def_scenario(V, F, sel, M)
    options = deform.DeformerOptions(rotational_proxies=args.rotational_proxies, linear_proxies=args.linear_proxies)
    deformer = deform.Deformer(scenario.model, options)
    summary = deformer.precompute(progress=lambda stage, f: print(f"  {stage:<16} {100 * f:5.1f} %"))
    print(f"{name}: n = {len(V)}, precompute {summary.total_seconds:.2f} s, reduced size {summary.reduced_size}")
    deformer.set_handles(scenario.handles)  # the handle patch; the fixed patch always holds

    os.makedirs(args.out, exist_ok=True)
    out = np.empty_like(V)  # every frame is written into this array, no copy
    transforms = path_transforms(V, sel, M, args.frames)
    poses, times = [("rest", V)], []
    for f, T in enumerate(transforms):
        t = time.perf_counter()
        deformer.frame(np.zeros((0, 3)), out=out, patch_transforms=T[None])
        times.append(time.perf_counter() - t)
        deform.write_mesh(os.path.join(args.out, f"{name}_{f:03d}.obj"), out, F)
        if f + 1 in (args.frames // 3, 2 * args.frames // 3, args.frames):
            poses.append((f"frame {f + 1}", out.copy()))
    last = deformer.last_frame
    residual = deformer.handle_residual(out)
    print(f"{args.frames} frames: median {1e3 * np.median(times):.2f} ms (Python call), last frame "
          f"{last.iterations} rounds, fixed-point residual {last.fixed_point_residual:.2e}, "
          f"handle residual {residual:.2e}")
    # The hand stops: finish the last pose to converged classic ARAP in full
    # space (warm-started from the reduced pose) and say how far it was.
    refiner = deform.Refiner(scenario.model, deform.RefineOptions(tolerance=1e-6))
    refined, finish = refiner.refine(scenario.handles, deform.HandleTargets(np.zeros((0, 3)), [transforms[-1]]), out)
    print(f"refine: {finish.rounds} rounds, {finish.seconds:.2f} s, ARAP energy "
          f"{deform.arap_energy(scenario.model, out):.4g} -> {finish.arap_energy:.4g}, reduced pose "
          f"{100 * finish.rms_from_input:.2f} % RMS / {100 * finish.max_from_input:.2f} % max of the diagonal away")
    deform.write_mesh(os.path.join(args.out, f"{name}_refined.obj"), refined, F)
    poses.append(("refined", refined))
    figure_path = os.path.join(args.out, f"{name}.png")
    figure(V, F, poses, figure_path, f"{name}: reduced ARAP, handle along a path")
    print(f"OBJ frames and {figure_path} written")
    return residual


if __name__ == "__main__":
    main()
