#!/usr/bin/env python3
"""The window's refine, end to end: handles that rest start a full-space
refine on the worker; the first frame a handle moves again cancels it and
steps the reduced deformer in that same frame (docs/viewer.md, "Refine").

Plays a recorded handle motion in `qpr view` (a real window under xvfb-run):
30 frames moving the bar's handle patch, 100 frames still, 30 frames moving,
and reads the window log (--window-log). Twice: with the default refine
(which may finish during the rest and be shown), and with one to the
converged shape by plain local-global (`--refine=0 --refine-plain`, thousands
of rounds on the bar), which is still running when the handle moves: its rest
is sized from the first play (1.5 times the frames it took to start its refine,
plus ten), so the refine has started and is a few hundred milliseconds in, on a
fast machine or a slow one. Asserts the order of events, not their times;
prints the cancel's measured cost for docs/performance.md.

    window_drag_cancel.py --qpr QPR --xvfb XVFB_RUN --data DIR --out DIR
"""
import argparse
import json
import math
import os
import statistics
import subprocess
import sys

MOVE, STILL = 30, 100


def motion(vertex_count, still):
    def t(dx):
        return [1, 0, 0, dx, 0, 1, 0, 0, 0, 0, 1, 0, 0, 0, 0, 1]
    frames = [[t(0.01 * i)] for i in range(MOVE)]
    frames += [[t(0.01 * (MOVE - 1))] for _ in range(still)]
    frames += [[t(0.01 * (MOVE + i))] for i in range(MOVE)]
    return {"format": "qpr-handle-motion", "version": 1, "vertex_count": vertex_count,
            "handles": [{"name": "handle", "patch": 1}], "frames": frames}


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--qpr", required=True)
    ap.add_argument("--xvfb", required=True)
    ap.add_argument("--data", required=True)
    ap.add_argument("--out", required=True)
    a = ap.parse_args()
    mesh = os.path.join(a.data, "bar.off")
    with open(mesh) as f:
        f.readline()
        vertex_count = int(f.readline().split()[0])
    failures, still = [], STILL
    for name, extra, states in (("default refine", [], ("running", "done")),
                                ("refine to the converged shape", ["--refine=0", "--refine-plain"], ("running",))):
        path = os.path.join(a.out, "drag_cancel_motion_%d.json" % len(extra))
        with open(path, "w") as f:
            json.dump(motion(vertex_count, still), f)
        log, found = play(a, mesh, path, name, extra, states, still)
        failures += [name + ": " + w for w in found]
        if log is None:
            break
        # The converged refine (hundreds of plain rounds on the bar, a few ms
        # each) must still run at the move: rest 1.5 times the frames the
        # first play took to start its refine, plus ten.
        first = next(i for i, f in enumerate(log["frames"]) if f["stepped"])
        rested = log["frames"][first + MOVE:first + MOVE + still]
        waited = next((i for i, f in enumerate(rested) if f.get("event") == "refine-start"), None)
        if waited is None:
            break
        still = min(STILL, int(math.ceil(1.5 * (waited + 1))) + 10)
    if failures:
        sys.exit("FAILED:\n  " + "\n  ".join(failures))
    print("ok")


def play(a, mesh, path, name, extra, states, rest):
    log_path = os.path.join(a.out, "drag_cancel_log_%d.json" % len(extra))
    if os.path.exists(log_path):
        os.remove(log_path)
    cmd = [a.xvfb, "-a", a.qpr, "view", mesh, "--sel", os.path.join(a.data, "bar.sel"), "--def",
           os.path.join(a.data, "bar.def"), "--frames", "2", "--size", "480x360", "--replay", path,
           "--max-frames", str(2 * MOVE + rest + 5), "--window-log", log_path] + extra
    run = subprocess.run(cmd, capture_output=True, text=True, timeout=300)
    if run.returncode != 0:
        return None, ["qpr view failed (%d):\n%s%s" % (run.returncode, run.stdout, run.stderr)]
    log = json.load(open(log_path))
    frames, still_s = log["frames"], log["refine_after_still_s"]
    failures = []

    def check(ok, what):
        if not ok:
            failures.append(what)

    # The replay starts with the first step (the precompute is done then).
    r = next(i for i, f in enumerate(frames) if f["stepped"])
    check(len(frames) == r + 2 * MOVE + rest + 5, "the log has the frames asked for (%d)" % len(frames))
    first, still, again = frames[r:r + MOVE], frames[r + MOVE:r + MOVE + rest], frames[r + MOVE + rest:]
    # The replay's first frame moves the handle from the scenario's pose.
    check(all(f["moved"] for f in first[1:]), "the first segment moves every frame")
    check(not any(f["moved"] for f in still), "the handle is still in the middle segment")
    check(all(f["moved"] for f in again[:MOVE]), "the last segment moves every frame")
    starts = [i for i, f in enumerate(still) if f.get("event") == "refine-start"]
    check(len(starts) == 1, "one refine starts while the handle rests (%s)" % starts)
    if starts:
        # The rest timer reads the clock inside each frame: from the top of the
        # last moving frame to the end of the starting one is at least the wait.
        begun = still[starts[0]]
        rested = begun["start_s"] + begun["frame_ms"] / 1e3 - first[-1]["start_s"]
        check(rested >= still_s, "the refine starts %.3f s after the last move, not before %.3f s" % (rested, still_s))
    check(not any(f["refined_shown"] for f in first + again), "no refined pose while the handle moves")
    cancel = again[0]
    check(cancel.get("event") == "refine-cancel", "the first moving frame cancels the refine (%s)" % cancel)
    check(cancel["stepped"], "and steps the reduced deformer in that same frame")
    check(cancel.get("worker_state") in states,
          "the worker was %s when cancelled (%s)" % (" or ".join(states), cancel.get("worker_state")))
    check(all(f["stepped"] and "event" not in f for f in again[1:MOVE]), "reduced frames follow, no refine event")
    # The 5 still frames after the motion may start the next refine, once
    # they have rested for the wait (on a loaded machine 5 frames can).
    tail = again[MOVE:]
    check(all(f.get("event") in (None, "refine-start") for f in tail), "the still frames after it at most start a refine")
    shown = [f for f in still if f.get("event") == "refine-shown"]
    moving_ms = [f["frame_ms"] for f in first[1:] + again[1:MOVE]]
    print("%s: refine %s before the move; cancel() %.1f µs (worker %s, %d rounds); the cancel frame %.1f ms, "
          "moving frames median %.1f ms, max %.1f ms"
          % (name, "shown" if shown else "still running", 1e3 * cancel.get("cancel_ms", -1), cancel.get("worker_state"),
             cancel.get("worker_rounds", -1), cancel["frame_ms"], statistics.median(moving_ms), max(moving_ms)))
    return log, failures


if __name__ == "__main__":
    main()
