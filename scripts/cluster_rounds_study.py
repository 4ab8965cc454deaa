#!/usr/bin/env python3
"""More rotational clusters, rounds run to convergence, float or double
products: on the Botsch–Sorkine cactus (.sel/.def, 8 frames, no time budget,
tolerance 1e-7) the last frame's rounds, its residual, and the RMS distance of
its pose from the classic ARAP shape converged by `qpr deform --refine=1e-9`
(over the bounding-box diagonal); docs/deform.md, "Rounds per frame".

    build/bin/qpreduce-python scripts/cluster_rounds_study.py [--clusters 27,100,200]
        [--qpr build/bin/qpr] [--data ../shared/data] [--work /tmp/qpreduce-clusters]
"""
import argparse
import os
import subprocess
import sys
import time

import numpy as np

from qpreduce import deform
from rounds_study import ROOT, read_off  # noqa: E402 (scripts/ is the script's own folder)


def main():
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--clusters", default="27,100,200")
    ap.add_argument("--qpr", default=os.path.join(ROOT, "build", "bin", "qpr"))
    ap.add_argument("--data", default=os.path.join(os.path.dirname(ROOT), "shared", "data"))
    ap.add_argument("--work", default="/tmp/qpreduce-clusters")
    a = ap.parse_args()
    os.makedirs(a.work, exist_ok=True)
    stem = os.path.join(a.data, "meshes", "botsch-sorkine", "cactus")
    converged = os.path.join(a.work, "cactus_converged.off")
    p = subprocess.run([a.qpr, "deform", stem + ".off", "--sel", stem + ".sel", "--def", stem + ".def", "--frames", "8",
                        "--refine=1e-9", "--out", converged], capture_output=True, text=True)
    if p.returncode != 0:
        sys.exit("qpr deform --refine failed:\n" + p.stdout + p.stderr)
    V, F = deform.read_mesh(stem + ".off")
    scenario = deform.sel_def_scenario(V, F, deform.read_sel(stem + ".sel"), deform.read_def(stem + ".def"), frames=8)
    target = read_off(converged)
    diagonal = np.linalg.norm(V.max(0) - V.min(0))
    print("| clusters | products | last frame: rounds | residual | RMS from converged ARAP | seconds |")
    print("|---|---|---|---|---|---|")
    for d in (int(x) for x in a.clusters.split(",")):
        for float_rounds in (True, False):
            options = deform.DeformerOptions(rotational_proxies=d, float_rounds=float_rounds, iterations=20000,
                                             tolerance=1e-7, time_budget=0.0)
            start = time.time()
            deformer = deform.Deformer(scenario.model, options)
            deformer.precompute()
            deformer.set_handles(scenario.handles, options=scenario.constraints)
            for targets in scenario.frames:
                pose = deformer.frame(targets)
            s = deformer.last_frame
            rms = np.sqrt(((pose - target) ** 2).sum(1).mean()) / diagonal
            print("| %d | %s | %d | %.1e | %.2f %% | %.0f |" % (d, "float" if float_rounds else "double", s.rounds,
                                                               s.fixed_point_residual, 100 * rms, time.time() - start))
            sys.stdout.flush()


if __name__ == "__main__":
    main()
