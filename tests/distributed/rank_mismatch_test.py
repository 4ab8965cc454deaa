#!/usr/bin/env python3
"""Ranks given different inputs stop together with one message (issue: MPI
ranks that agree). Under `mpirun` with an MPMD line (`-np 1 qpr … : -np 1 qpr
…`), each case gives rank 1 another option value, another file or another
subcommand than rank 0; every rank must end within the bound with exit 2 and
rank 0's one message naming what differs and on which rank (apps/qpr/
rank_agreement.h). The same file at another path is not a difference.

    rank_mismatch_test.py QPR_BINARY MPIRUN WORK_DIR
"""
import math
import os
import shutil
import subprocess
import sys

BOUND = 60  # seconds: a hang fails the case


def tube(rings=6, around=8, height=0.8):
    V, F = [], []
    for r in range(rings):
        for a in range(around):
            t = 2 * math.pi * a / around
            V.append((math.cos(t), math.sin(t), height * r))
    for r in range(rings - 1):
        for a in range(around):
            i, j = r * around + a, r * around + (a + 1) % around
            F += [(i, j, j + around), (i, j + around, i + around)]
    off = "OFF\n%d %d 0\n" % (len(V), len(F)) + "".join("%r %r %r\n" % v for v in V)
    off += "".join("3 %d %d %d\n" % f for f in F)
    sel = "".join("%d\n" % (0 if v[2] < 0.1 else 2 if v[2] > height * (rings - 1) - 0.1 else 1) for v in V)
    return off, sel


def main():
    qpr, mpirun, work = sys.argv[1:4]
    shutil.rmtree(work, ignore_errors=True)
    os.makedirs(os.path.join(work, "node1"))
    off, sel = tube()
    taller, _ = tube(height=0.9)
    files = {"tube.off": off, "node1/tube.off": off, "taller.off": taller, "tube.sel": sel,
             "tube.def": "0 -1 0 0\n1 0 0 0\n0 0 1 0.5\n0 0 0 1\n",
             # A tiny QP (H = I, C = e1) and two demand folders that differ in b.
             "H.mtx": "%%MatrixMarket matrix coordinate real symmetric\n4 4 4\n1 1 1\n2 2 1\n3 3 1\n4 4 1\n",
             "C.mtx": "%%MatrixMarket matrix coordinate real general\n4 1 1\n1 1 1\n"}
    # One scene text in three folders: the files it names (by relative path)
    # are the same on node1 and another mesh in node2.
    scene = ('{"mesh": "tube.off", "patches": [{"type": "fixed", "sel": {"file": "tube.sel", "role": "fixed"}}], '
             '"handles": [{"sel": {"file": "tube.sel", "role": 2}, "def": "tube.def"}]}')
    for folder, mesh in (("", off), ("node1/", off), ("node2/", taller)):
        files.update({folder + "s.json": scene, folder + "tube.off": mesh, folder + "tube.sel": sel,
                      folder + "tube.def": "0 -1 0 0\n1 0 0 0\n0 0 1 0.5\n0 0 0 1\n"})
    for folder, b in (("dem", "1"), ("dem2", "2")):
        files[folder + "/A_d0.mtx"] = "%%MatrixMarket matrix coordinate real general\n4 1 1\n2 1 1\n"
        files[folder + "/b_d0.mtx"] = "%%MatrixMarket matrix array real general\n1 1\n" + b + "\n"
    for name, text in files.items():
        os.makedirs(os.path.dirname(os.path.join(work, name)), exist_ok=True)
        with open(os.path.join(work, name), "w") as f:
            f.write(text)
    W = lambda name: os.path.join(work, name)  # noqa: E731
    small = ["--sel", W("tube.sel"), "--def", W("tube.def"), "--linear-proxies", "6", "--backend", "mumps"]

    def pre(mesh, *extra, clusters="4"):
        return [qpr, "precompute", W(mesh), *small, "--rotational-proxies", clusters, "--cache", W("c.qpr"), *extra]

    def pre_scene(path):
        return [qpr, "precompute", "--scene", W(path), "--linear-proxies", "6", "--rotational-proxies", "4",
                "--backend", "mumps", "--cache", W("c.qpr")]

    cases = [
        # (name, rank 0's command, rank 1's command, expected words; None: must succeed)
        ("another proxy count", pre("tube.off"), pre("tube.off", clusters="5"),
         ["--rotational-proxies differs on rank 1"]),
        ("another --alpha", pre("tube.off"), pre("tube.off", "--alpha", "0.5"), ["--alpha differs on rank 1"]),
        ("another mesh", pre("tube.off"), pre("taller.off"), ["the contents of MESH differ on rank 1"]),
        ("the same mesh at another path", pre("tube.off"), pre("node1/tube.off"), None),
        ("a scene naming another mesh", pre_scene("s.json"), pre_scene("node2/s.json"),
         ["the contents of --scene differ on rank 1"]),
        ("the same scene and files at another path", pre_scene("s.json"), pre_scene("node1/s.json"), None),
        ("another grid side", [qpr, "precompute-gmrf", "--side", "20", "--candidates", "10"],
         [qpr, "precompute-gmrf", "--side", "21", "--candidates", "10"], ["--side differs on rank 1"]),
        ("qp: another demand folder", [qpr, "qp", "--H", W("H.mtx"), "--C", W("C.mtx"), "--demands", W("dem"),
                                       "--backend", "mumps"],
         [qpr, "qp", "--H", W("H.mtx"), "--C", W("C.mtx"), "--demands", W("dem2"), "--backend", "mumps"],
         ["the contents of --demands differ on rank 1"]),
        ("another subcommand", pre("tube.off"), [qpr, "precompute-gmrf", "--side", "20", "--candidates", "10"],
         ["rank 1 runs another subcommand than rank 0"]),
    ]
    failures = 0
    for name, first, second, words in cases:
        cmd = [mpirun, "--oversubscribe", "-np", "1", *first, ":", "-np", "1", *second]
        try:
            p = subprocess.run(cmd, capture_output=True, text=True, timeout=BOUND)
        except subprocess.TimeoutExpired:
            print(f"FAIL {name}: still running after {BOUND} s")
            failures += 1
            continue
        problems = []
        if words is None:
            if p.returncode != 0:
                problems.append(f"exit {p.returncode}, expected 0")
        else:
            if p.returncode == 0:
                problems.append("exit 0, expected a failure")
            errors = [line for line in p.stderr.splitlines() if "error:" in line]
            if len(errors) != 1:
                problems.append(f"{len(errors)} error lines, expected one (from rank 0)")
            for w in words + ["every rank must run the same command on the same files"]:
                if w not in p.stderr:
                    problems.append(f"stderr lacks {w!r}")
        if problems:
            failures += 1
            print(f"FAIL {name}: {'; '.join(problems)}\n  $ {' '.join(cmd)}\n{p.stderr[-1500:]}")
        else:
            print(f"ok   {name}")
    # Under an address-space limit every rank says "out of memory" within the
    # bound (apps/qpr/blas_memory.h; OpenBLAS used to retry its buffer for ever)
    # and mpirun ends with its exit 2. The limit is the ranks' own (a shell's
    # ulimit before exec): mpirun under it crashed or hung now and then
    # itself (SIGSEGV in 18 of 25 tries here, one 60 s hang in CI).
    rank = pre("tube.off")
    cmd = [mpirun, "--oversubscribe", "-np", "2", "/bin/sh", "-c", 'ulimit -v %d && exec "$@"' % (146 * 1024), "sh",
           *rank]
    try:
        p = subprocess.run(cmd, capture_output=True, text=True, timeout=BOUND)
        if p.returncode != 2 or "out of memory: the address-space limit (ulimit -v)" not in p.stderr:
            failures += 1
            print(f"FAIL under ulimit -v: exit {p.returncode}\n{p.stderr[-1500:]}")
        else:
            print("ok   under ulimit -v 146 MB: out of memory, exit 2, no hang")
    except subprocess.TimeoutExpired:
        failures += 1
        print(f"FAIL under ulimit -v: still running after {BOUND} s")
    cases.append(None)
    print(f"{len(cases) - failures} of {len(cases)} cases passed")
    return 1 if failures else 0


if __name__ == "__main__":
    sys.exit(main())
