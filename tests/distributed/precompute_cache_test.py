#!/usr/bin/env python3
"""`qpr precompute --backend mumps` under mpirun writes a cache `qpr deform` loads.

    precompute_cache_test.py QPR_BINARY MPIRUN SHARED_DIR WORK_DIR

On the Botsch–Sorkine cactus (.sel/.def): a cache from `mpirun -np 2 qpr
precompute --backend mumps` and one from the single-process CHOLMOD build
(`qpr precompute --backend cholmod`) are each loaded by `qpr deform --cache`
(which must say "loaded from"); the two deformed meshes agree to 1e-6 of the
mesh size (not bit for bit: the two double bases differ by rounding, see
docs/scaling.md, "What is bit-identical").

Bit for bit, where it holds by construction (the OBJ writer prints each
coordinate's shortest round-trip form, so equal files are equal doubles):
  * the 2-rank cache loaded twice gives the same frames: the frames are a
    function of the cache's bytes (the float basis is stored as it is);
  * two caches from `mpirun -np 1 … --backend mumps` are the same file, with
    SCOTCH_PTHREAD_NUMBER=1 (Scotch 7's threaded ordering is not
    reproducible); two 2-rank caches are not compared: MUMPS on more than one
    process assembles in message-arrival order and is not reproducible.

The same with `--out-of-core DIR` (MUMPS's factor on disk): the pose agrees
with the CHOLMOD cache's to 1e-6 too, and DIR is empty afterwards.

Then failures: an unwritable cache path, and an --out-of-core directory that
does not exist, make the MPI job end with a message and a non-zero exit,
within the CTest timeout. Exits 77 (skipped)
when the shared data is absent.
"""
import os
import subprocess
import sys


def run(cmd, expect_ok=True, env=None):
    p = subprocess.run(cmd, capture_output=True, text=True, timeout=240, env=env)
    if expect_ok and p.returncode != 0:
        sys.exit(f"FAILED ({p.returncode}): {' '.join(cmd)}\n{p.stdout}\n{p.stderr}")
    return p


def vertices(path):
    with open(path) as f:
        return [tuple(float(x) for x in line.split()[1:4]) for line in f if line.startswith("v ")]


def same_file(a, b):
    with open(a, "rb") as f, open(b, "rb") as g:
        return f.read() == g.read()


def deform(qpr, scenario, cache, out):
    # A fixed count of rounds (8, no cold start to a tolerance): the poses of
    # two caches then differ by what their subspaces differ by, not by where a
    # tolerance test happened to stop the rounds.
    p = run([qpr, "deform", *scenario, "--cache", cache, "--out", out, "--cold-start-rounds", "0", "--iterations", "8",
             "--tolerance", "0", "--time-budget-ms", "0"])
    if "loaded from" not in p.stdout + p.stderr:
        sys.exit(f"FAILED: qpr deform did not load {cache}:\n{p.stdout}\n{p.stderr}")
    return out


def bit_identical(qpr, mpirun, scenario, work, cache_np2):
    """The bit-exact checks of the docstring."""
    a = deform(qpr, scenario, cache_np2, os.path.join(work, "cactus_np2_load1.obj"))
    b = deform(qpr, scenario, cache_np2, os.path.join(work, "cactus_np2_load2.obj"))
    if not same_file(a, b):
        sys.exit("FAILED: the same 2-rank cache loaded twice gave different frames")
    env = dict(os.environ, SCOTCH_PTHREAD_NUMBER="1")
    one_rank = [os.path.join(work, f"cactus_mumps_np1_{i}.cache") for i in (1, 2)]
    for c in one_rank:
        run([mpirun, "--oversubscribe", "-x", "SCOTCH_PTHREAD_NUMBER", "-np", "1", qpr, "precompute", *scenario,
             "--backend", "mumps", "--cache", c], env=env)
    if not same_file(*one_rank):
        sys.exit("FAILED: two 1-rank MUMPS caches (SCOTCH_PTHREAD_NUMBER=1) differ")
    print("bit-identical: the 2-rank cache's frames on reload; two 1-rank MUMPS caches")


def main():
    qpr, mpirun, shared, work = sys.argv[1:5]
    # $QPREDUCE_SHARED_DATA names the data folder when set (tests/shared_data.h).
    data = os.path.join(os.environ.get("QPREDUCE_SHARED_DATA", os.path.join(shared, "data")), "meshes",
                        "botsch-sorkine")
    mesh = os.path.join(data, "cactus.off")
    if not os.path.exists(mesh):
        print(f"skipped: {mesh} is absent (the shared data lives in ../shared next to the checkout, "
              "or where QPREDUCE_SHARED_DATA says)")
        return 77
    os.makedirs(work, exist_ok=True)
    scenario = [mesh, "--sel", os.path.join(data, "cactus.sel"), "--def", os.path.join(data, "cactus.def")]
    caches = {"mumps": os.path.join(work, "cactus_mumps_np2.cache"),
              "mumps_ooc": os.path.join(work, "cactus_mumps_np2_ooc.cache"),
              "cholmod": os.path.join(work, "cactus_cholmod.cache")}
    for c in caches.values():
        if os.path.exists(c):
            os.remove(c)
    ooc = os.path.join(work, "ooc")
    os.makedirs(ooc, exist_ok=True)
    run([mpirun, "--oversubscribe", "-np", "2", qpr, "precompute", *scenario, "--backend", "mumps",
         "--cache", caches["mumps"]])
    # The factor out of core (--out-of-core): the same subspace, no files left.
    p = run([mpirun, "--oversubscribe", "-np", "2", qpr, "precompute", *scenario, "--backend", "mumps",
             "--out-of-core", ooc, "--cache", caches["mumps_ooc"]])
    if "factor out of core" not in p.stdout or os.listdir(ooc):
        sys.exit(f"FAILED: --out-of-core not reported, or files left in {ooc}: {os.listdir(ooc)}\n{p.stdout}")
    run([qpr, "precompute", *scenario, "--backend", "cholmod", "--cache", caches["cholmod"]])
    poses = {}
    for name, cache in caches.items():
        poses[name] = vertices(deform(qpr, scenario, cache, os.path.join(work, f"cactus_{name}.obj")))
    b = poses["cholmod"]
    size = max(max(v[i] for v in b) - min(v[i] for v in b) for i in range(3))
    for name in ("mumps", "mumps_ooc"):
        a = poses[name]
        if len(a) != len(b) or not a:
            sys.exit(f"FAILED: {len(a)} and {len(b)} vertices")
        worst = max(abs(x - y) for u, v in zip(a, b) for x, y in zip(u, v))
        print(f"max vertex difference {name} (np 2) vs CHOLMOD caches: {worst:.3e} (mesh size {size:.3g})")
        if not worst <= 1e-6 * size:
            sys.exit(f"FAILED: the {name} and CHOLMOD poses differ by more than 1e-6 of the mesh size")
    bit_identical(qpr, mpirun, scenario, work, caches["mumps"])

    # A rank-0 failure (no such directory) ends the job with a message.
    p = run([mpirun, "--oversubscribe", "-np", "2", qpr, "precompute", *scenario, "--backend", "mumps",
             "--cache", os.path.join(work, "no-such-dir", "x.cache")], expect_ok=False)
    if p.returncode == 0 or "qpr precompute: error" not in p.stderr:
        sys.exit(f"FAILED: expected a failed job with a message, got {p.returncode}:\n{p.stderr}")
    # An out-of-core directory that does not exist: refused with its name.
    p = run([mpirun, "--oversubscribe", "-np", "2", qpr, "precompute", *scenario, "--backend", "mumps",
             "--out-of-core", os.path.join(work, "no-such-dir"), "--cache", os.path.join(work, "y.cache")],
            expect_ok=False)
    if p.returncode == 0 or "is not a directory" not in p.stderr:
        sys.exit(f"FAILED: expected --out-of-core to a missing directory to fail with a message, got "
                 f"{p.returncode}:\n{p.stderr}")
    print("ok")
    return 0


if __name__ == "__main__":
    sys.exit(main())
