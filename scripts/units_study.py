#!/usr/bin/env python3
"""The shared capped cylinder scaled by 10^k: how far each scale's reduced
pose (mapped back) ends from the unscaled one, over the bounding-box
diagonal, when the frames run a fixed count of accelerated rounds (the
defaults' Anderson window), a fixed count of plain rounds, or rounds to a
tight tolerance; and, for the accelerated rounds, how that distance grows
with the rounds of the last frame (docs/robustness.md, "Units").

    build/bin/qpreduce-python scripts/units_study.py [--data ../shared/data]
        [--scales 1e-30,1e-20,1e6,1e9,1e25] [--rounds 60]
"""
import argparse
import os
import sys

import numpy as np

from qpreduce import deform


def load(data):
    folder = os.path.join(data, "meshes", "botsch-sorkine")
    if not os.path.exists(os.path.join(folder, "cylinder.off")):
        sys.exit("%s: no cylinder.off (the shared data's botsch-sorkine folder)" % folder)
    V, F = deform.read_mesh(os.path.join(folder, "cylinder.off"))
    return V, F, deform.read_sel(os.path.join(folder, "cylinder.sel")), deform.read_def(os.path.join(folder, "cylinder.def"))


def last_pose(mesh, scale, options, last_rounds=None, frames=4):
    """The last of `frames` frames at this scale, mapped back (divided by the
    scale); the last frame runs `last_rounds` rounds when given."""
    V, F, sel, M = mesh
    Ms = M.copy()
    Ms[:3, 3] *= scale
    sc = deform.sel_def_scenario(V * scale, F, sel, Ms, frames=frames)
    d = deform.Deformer(sc.model, deform.DeformerOptions(**options))
    d.precompute()
    d.set_handles(sc.handles)
    out = np.empty_like(V)
    for f, targets in enumerate(sc.frames):
        if f == frames - 1 and last_rounds is not None:
            d.set_rounds(last_rounds)
        d.frame(targets, out=out)
    return out / scale, d.last_frame


def main():
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--data", default=os.path.normpath(os.path.join(os.path.abspath(__file__), "..", "..", "..", "shared", "data")))
    ap.add_argument("--scales", default="1e-30,1e-20,1e6,1e9,1e25")
    ap.add_argument("--rounds", type=int, default=60)
    a = ap.parse_args()
    mesh = load(a.data)
    diagonal = np.linalg.norm(mesh[0].max(0) - mesh[0].min(0))
    scales = [float(s) for s in a.scales.split(",")]
    fixed = dict(iterations=a.rounds, tolerance=0.0, time_budget=0.0, cold_start_rounds=0)
    settings = [("accelerated, %d rounds a frame" % a.rounds, fixed),
                ("plain, %d rounds a frame" % a.rounds, dict(fixed, anderson_window=0)),
                ("to a fixed-point residual of 1e-13", dict(iterations=5000, tolerance=1e-13, time_budget=0.0))]
    print("| frames run | " + " | ".join("%g" % s for s in scales) + " | last frame's residual |")
    print("|---|" + "---|" * (len(scales) + 1))
    for name, options in settings:
        base, summary = last_pose(mesh, 1.0, options)
        cells = ["%.1e" % (np.abs(last_pose(mesh, s, options)[0] - base).max() / diagonal) for s in scales]
        print("| %s | %s | %.1e |" % (name, " | ".join(cells), summary.fixed_point_residual))
    print()
    print("Accelerated rounds, scale %g: the distance after k rounds of the last frame" % scales[2 % len(scales)])
    print()
    ks = [k for k in (1, 10, 20, 30, 35, 40, 50, 60) if k <= a.rounds]
    print("| k | " + " | ".join(str(k) for k in ks) + " |")
    print("|---|" + "---|" * len(ks))
    row = []
    for k in ks:
        base, _ = last_pose(mesh, 1.0, fixed, last_rounds=k)
        other, _ = last_pose(mesh, scales[2 % len(scales)], fixed, last_rounds=k)
        row.append("%.1e" % (np.abs(other - base).max() / diagonal))
    print("| distance | " + " | ".join(row) + " |")


if __name__ == "__main__":
    main()
