"""qpreduce.deform: frames run while another deformer precomputes (the GIL is
released), a shared deformer stays consistent, and 10⁴ frames do not leak."""

import sys
import threading

import numpy as np

from qpreduce import deform
from conftest import rss_growth
from test_deform import OPTIONS, make_deformer


def test_frames_run_while_another_deformer_precomputes():
    deformer, scenario = make_deformer()
    out = np.empty((deformer.vertex_count, 3))
    targets = scenario.frames[-1]
    # The fixed point of repeated frames at one pose: frames keep warm-starting,
    # so compare against the same sequence run serially.
    serial, _ = make_deformer()
    V, F = deform.shapes.capped_cylinder(1.0, 12.0, 48, 60)  # 2,882 vertices
    big = deform.Deformer(V, F, deform.DeformerOptions(**OPTIONS))
    result = {}
    started = threading.Event()

    def precompute():
        started.set()
        result["summary"] = big.precompute(progress=lambda stage, fraction: None)

    thread = threading.Thread(target=precompute)
    thread.start()
    started.wait()
    frames = 0
    while thread.is_alive():
        deformer.frame(targets, out=out)
        assert np.array_equal(out, serial.frame(targets))
        frames += 1
    thread.join()
    assert result["summary"].ok() and big.ready
    # The precompute lasts well over 100 ms; had it held the GIL (or the
    # progress callback deadlocked), no frame could have run meanwhile.
    assert frames >= 20, f"only {frames} frames during a {result['summary'].total_seconds:.3f} s precompute"


def test_one_deformer_shared_by_threads():
    deformer, scenario = make_deformer()
    n = deformer.vertex_count
    errors = []

    def run(offset):
        out = np.empty((n, 3))
        for i in range(300):
            try:
                deformer.frame(scenario.frames[(i + offset) % len(scenario.frames)], out=out)
                if not np.all(np.isfinite(out)):
                    errors.append("non-finite frame")
            except Exception as error:  # noqa: BLE001 — collected and asserted below
                errors.append(repr(error))

    threads = [threading.Thread(target=run, args=(k,)) for k in range(3)]
    for thread in threads:
        thread.start()
    for thread in threads:
        thread.join()
    assert not errors, errors[:3]


def test_no_leak_over_ten_thousand_frames():
    deformer, scenario = make_deformer()
    out = np.empty((deformer.vertex_count, 3))
    targets = [np.ascontiguousarray(f.patch_transforms[0])[None] for f in scenario.frames]
    points = np.zeros((0, 3))
    refcounts = (sys.getrefcount(out), sys.getrefcount(points))

    def run(count):
        for i in range(count):
            deformer.frame(points, out=out, patch_transforms=targets[i % len(targets)])
            if i % 100 == 0:
                deformer.last_frame  # a copy of the summary, freed at once
                deformer.frame(scenario.frames[0])  # a new array, freed at once

    growth = rss_growth(run)
    # A leaked n × 3 array per frame would add 10⁴ · 7.7 KB ≈ 77 MB.
    assert growth < 2 * 1024 * 1024, f"RSS grew by {growth / 1024:.0f} KiB over 10⁴ frames"
    assert (sys.getrefcount(out), sys.getrefcount(points)) == refcounts
