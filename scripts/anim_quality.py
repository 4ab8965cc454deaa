#!/usr/bin/env python3
"""Re-measure the point-handle (`.anim`) rows of docs/quality.md's main table
with a new `qpr`, against the reference meshes of an earlier full run of
scripts/quality_study.py (its --work directory): RMS and max distance over the
bounding-box diagonal and the classic-energy ratio, with second-order steps
(the default) and with rounds only (--no-second-order).

    python3 scripts/anim_quality.py --work STUDY_WORK_DIR [--qpr build/bin/qpr] [--out DIR]

Cheap (one `qpr deform` per row and mode); the references are not recomputed.
"""
import argparse
import json
import os
import subprocess
import sys

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
from quality_study import deviation, read_off_vertices  # noqa: E402

ROWS = [("cactus", "moved_hansel"), ("cactus", "origin_hansel"), ("cactus", "rotated_hansel"),
        ("cylinder", "newbend_hansel"), ("cylinder", "rotated_hansel"), ("bar", "rotated_hansel")]


def main():
    root = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--work", required=True, help="the work directory of a full quality_study.py run")
    ap.add_argument("--qpr", default=os.path.join(root, "build", "bin", "qpr"))
    ap.add_argument("--data", default=os.path.join(os.path.dirname(root), "shared", "data"))
    ap.add_argument("--out", default=None, help="where the poses and reports go (default: WORK/anim_quality)")
    a = ap.parse_args()
    out_dir = a.out or os.path.join(a.work, "anim_quality")
    os.makedirs(out_dir, exist_ok=True)
    print("| scenario | RMS / max before | RMS / max, Newton steps | RMS / max, rounds only | energy ratio before → after |")
    print("|---|---|---|---|---|")
    for model, pose in ROWS:
        tag = "anim_%s_%s" % (model, pose)
        report = os.path.join(a.work, "compare_%s.json" % tag)
        if not os.path.exists(report):
            sys.exit("anim_quality: %s is missing: run scripts/quality_study.py with --work %s first" % (report, a.work))
        rep = json.load(open(report))
        ref, diag, E = rep["reference"]["mesh"], rep["bounding_box_diagonal"], rep["reference"]["arap_energy"]
        mesh = os.path.join(a.data, "meshes", "botsch-sorkine", model + ".off")
        anim = os.path.join(a.work, "anim_%s_%s_8.anim" % (model, pose))
        res = {}
        for label, extra in (("newton", []), ("rounds", ["--no-second-order"])):
            o, r = (os.path.join(out_dir, "%s_%s.%s" % (tag, label, ext)) for ext in ("off", "json"))
            subprocess.run([a.qpr, "deform", mesh, "--anim", anim, "--out", o, "--report", r] + extra, check=True,
                           stdout=subprocess.DEVNULL, env=dict(os.environ, OMP_NUM_THREADS="1"))
            rms, mx = deviation(read_off_vertices(o), read_off_vertices(ref), diag)
            res[label] = (rms, mx, json.load(open(r))["arap_energy"])
        print("| %s/%s | %.2f %% / %.2f %% | %.2f %% / %.2f %% | %.2f %% / %.2f %% | %.2f → %.2f |" % (
            model, pose, 100 * rep["rms_deviation"], 100 * rep["max_deviation"], 100 * res["newton"][0],
            100 * res["newton"][1], 100 * res["rounds"][0], 100 * res["rounds"][1], rep["reduced"]["arap_energy"] / E,
            res["newton"][2] / E), flush=True)


if __name__ == "__main__":
    main()
