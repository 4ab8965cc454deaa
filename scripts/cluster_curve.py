#!/usr/bin/env python3
"""More rotational clusters on the Botsch–Sorkine suite: for each model and
cluster count, the reduced pose run to its fixed point (rounds to 1e-9, no
budget) and with the defaults, each against the classic ARAP shape converged
by `qpr deform --refine=1e-9`: RMS vertex distance over the bounding-box
diagonal, the classic ARAP energy's ratio to the converged one, and with the
defaults the median µs of a round and milliseconds of rounds a frame (the
rest of a frame, the threaded reconstruction, does not depend on the
clusters; docs/deform.md, "How many clusters").

    build/bin/qpreduce-python scripts/cluster_curve.py [--models cylinder,cactus,bar,bumpy_plane]
        [--clusters 10,27,50,100,200] [--qpr build/bin/qpr] [--data ../shared/data]
        [--work /tmp/qpreduce-curve] [--threads 2]
"""
import json
import os
import sys

import numpy as np

from rounds_study import read_off, run, suite_arguments  # noqa: E402 (scripts/ is the script's own folder)

CONVERGED = ["--iterations", "20000", "--tolerance", "1e-9", "--time-budget-ms", "0"]


def main():
    ap = suite_arguments(__doc__.split("\n\n")[0], "/tmp/qpreduce-curve", 2)
    ap.add_argument("--clusters", default="10,27,50,100,200")
    a = ap.parse_args()
    os.makedirs(a.work, exist_ok=True)
    folder = os.path.join(a.data, "meshes", "botsch-sorkine")
    print("| model | clusters | converged: RMS | energy ratio | defaults: RMS | energy ratio | round µs | rounds ms a frame |")
    print("|---|---|---|---|---|---|---|---|")
    for model in a.models.split(","):
        mesh = os.path.join(folder, model + ".off")
        if not os.path.exists(mesh):
            sys.exit("%s: no such model (the shared data's botsch-sorkine folder)" % mesh)
        scenario = [a.qpr, "deform", mesh, "--sel", os.path.join(folder, model + ".sel"), "--def",
                    os.path.join(folder, model + ".def"), "--frames", "8"]
        converged, converged_report = (os.path.join(a.work, "%s_converged.%s" % (model, ext)) for ext in ("off", "json"))
        if not os.path.exists(converged_report):
            run(scenario + ["--refine=1e-9", "--out", converged, "--report", converged_report], a.threads)
        target = read_off(converged)
        target_energy = json.load(open(converged_report))["arap_energy"]
        rest = read_off(mesh)
        diagonal = np.linalg.norm(rest.max(0) - rest.min(0))
        for d in (int(x) for x in a.clusters.split(",")):
            cells = []
            base = scenario + ["--rotational-proxies", str(d), "--cache", os.path.join(a.work, "%s_%d.cache" % (model, d))]
            for name, extra in (("converged", CONVERGED), ("defaults", [])):
                pose, report = (os.path.join(a.work, "%s_%d_%s.%s" % (model, d, name, ext)) for ext in ("off", "json"))
                run(base + extra + ["--out", pose, "--report", report], a.threads)
                r = json.load(open(report))
                rms = np.sqrt(((read_off(pose) - target) ** 2).sum(1).mean()) / diagonal
                cells += ["%.2f %%" % (100 * rms), "%.3f" % (r["arap_energy"] / target_energy)]
            rounds_ms = 1e-3 * r["iteration_us"] * float(np.median(r["rounds_per_frame"][1:]))  # after the cold start
            cells += ["%.1f" % r["iteration_us"], "%.2f" % rounds_ms]
            print("| %s | %d | %s |" % (model, d, " | ".join(cells)))
            sys.stdout.flush()


if __name__ == "__main__":
    main()
