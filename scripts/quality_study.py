#!/usr/bin/env python3
"""Quality study of the reduced ARAP deformer against full-space references.

One command regenerates the measured tables of docs/quality.md (between the
`<!-- quality_study:NAME -->` markers) and the figures docs/figures/quality_*.png:

    python3 scripts/quality_study.py             # full study, serially, under `nice -n 10`
    python3 scripts/quality_study.py --quick     # smoke run: cylinder only, short settings,
                                                 # writes to the work dir, not to docs/

Every number comes from `qpr compare --report` (reduced vs the full-space
references) or `qpr deform --report` plus the vertex distance of its last pose
to the reference mesh `qpr compare` wrote (sweeps: the reference is solved once
per scenario, not once per setting). The figures are drawn with matplotlib
(python3-matplotlib, scripts/plots.py).

Runs are kept in the work directory (default /tmp/qpreduce-quality): with
--resume a run whose command line is unchanged is not repeated.
"""
import argparse
import glob
import hashlib
import json
import math
import os
import platform
import shlex
import shutil
import subprocess
import sys
import time

from quality_tables import TARGET_RATIO, TARGET_RMS, TARGET_SPEEDUP, figures, fragments, label, short, splice  # noqa: E402

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))

# ---------------------------------------------------------------------------
# Study configuration (the caps are recorded in the doc by the run-info table)
# ---------------------------------------------------------------------------
FULL = dict(
    frames=8,                       # frames from rest to the pose (.sel/.def --frames, .anim interpolated)
    lg_rounds={"default": 3000, "bar": 5000, "solid_cylinder": 1000},   # local-global iteration caps
    ceres=[("cactus", 60), ("cylinder", 60)],    # (.sel/.def model, LM iteration cap)
    ladder=[("bumpy_plane", [100, 300, 1000]), ("cactus", [100, 300, 1000])],  # local-global stopped early
    selv=["bar", "bumpy_plane", "cactus", "cylinder"],
    tet=[("solid_cylinder", "cylinder")],        # (tets/NAME.node, Botsch–Sorkine .sel/.def of its surface)
    anim=[("cactus", "moved_hansel"), ("cactus", "origin_hansel"), ("cactus", "rotated_hansel"),
          ("cylinder", "newbend_hansel"), ("cylinder", "rotated_hansel"), ("bar", "rotated_hansel")],
    # E' references (--energy modified): the model's own minimiser, to split the error.
    modified=[("sel", "cactus", {}), ("sel", "cactus", {"alpha": 0.01}),
              ("sel", "cactus", {"rotational-proxies": 100}),
              ("sel", "cactus", {"alpha": 0.01, "rotational-proxies": 100}), ("sel", "cylinder", {})],
    rot_sweep=[5, 9, 17, 27, 32, 64],
    rot_scen=[("sel", "cactus"), ("sel", "cylinder"), ("sel", "bar"), ("anim", "cactus/moved_hansel"),
              ("anim", "cylinder/rotated_hansel")],
    lin_sweep=[9, 17, 33, 65, 129],
    lin_scen=[("anim", "cactus/moved_hansel"), ("anim", "cylinder/rotated_hansel"), ("anim", "bar/rotated_hansel")],
    alpha_sweep=[0.01, 0.05, 0.1, 1, 10],
    alpha_scen=[("sel", "cactus"), ("sel", "cylinder"), ("anim", "cylinder/rotated_hansel")],
    beta_sweep=[0, 0.1, 1],
    beta_scen=[("sel", "cactus")],
    # the paper demo's own proxies (.id files) for its recorded poses: (scenario, linear groups, clusters)
    paper_ids=[("cactus/moved_hansel", "cactus_cluster27.id", "cactus_rotation25.id"),
               ("cylinder/rotated_hansel", "cylinder_cluster27.id", "cylinder_rotation25.id"),
               ("bar/rotated_hansel", "bar_cluster27.id", "bar_rotation.id")],
    conv_frames=[1, 8, 32, 128, 512],
    timing=["bar", "bumpy_plane", "cactus", "cylinder"],   # 64 frames, all threads and one thread
    conv_iters=[8, 32],
    conv_scen=[("sel", "bar", {}), ("sel", "bumpy_plane", {}), ("sel", "cactus", {}), ("sel", "cylinder", {}),
               ("sel", "cactus", {"alpha": 0.01}), ("sel", "cactus", {"alpha": 0.01, "rotational-proxies": 100})],
)
QUICK = dict(
    frames=2,
    lg_rounds={"default": 100},
    ceres=[("cylinder", 2)],
    ladder=[("cylinder", [10, 30])],
    selv=["cylinder"],
    tet=[],
    anim=[("cylinder", "rotated_hansel")],
    modified=[("sel", "cylinder", {})],
    rot_sweep=[5, 9],
    rot_scen=[("sel", "cylinder")],
    lin_sweep=[9, 17],
    lin_scen=[("anim", "cylinder/rotated_hansel")],
    alpha_sweep=[0.1, 1],
    alpha_scen=[("sel", "cylinder")],
    beta_sweep=[0, 0.1],
    beta_scen=[("sel", "cylinder")],
    paper_ids=[("cylinder/rotated_hansel", "cylinder_cluster27.id", "cylinder_rotation25.id")],
    conv_frames=[1, 2],
    timing=["cylinder"],
    conv_iters=[8],
    conv_scen=[("sel", "cylinder", {})],
)


# ---------------------------------------------------------------------------
# Small helpers
# ---------------------------------------------------------------------------
def read_off_vertices(path):
    with open(path) as f:
        tokens = []
        for line in f:
            line = line.split("#", 1)[0].strip()
            if line:
                tokens.extend(line.split())
            if len(tokens) >= 4 and tokens[0].upper() == "OFF":
                nv = int(tokens[1])
                if len(tokens) >= 4 + 3 * nv:
                    break
    if tokens[0].upper() != "OFF":
        raise RuntimeError(path + ": not an OFF file")
    nv = int(tokens[1])
    vals = [float(t) for t in tokens[4:4 + 3 * nv]]
    return [vals[3 * i:3 * i + 3] for i in range(nv)]


def bbox_diagonal(V):
    lo = [min(v[k] for v in V) for k in range(3)]
    hi = [max(v[k] for v in V) for k in range(3)]
    return math.sqrt(sum((hi[k] - lo[k]) ** 2 for k in range(3)))


def deviation(A, B, diag):
    if len(A) != len(B):
        raise RuntimeError("vertex counts differ (%d vs %d)" % (len(A), len(B)))
    s, m = 0.0, 0.0
    for a, b in zip(A, B):
        d2 = (a[0] - b[0]) ** 2 + (a[1] - b[1]) ** 2 + (a[2] - b[2]) ** 2
        s += d2
        m = max(m, d2)
    return math.sqrt(s / len(A)) / diag, math.sqrt(m) / diag


def write_interpolated_anim(src, rest_off, frames, dst):
    """The recorded pose of `src`, reached in `frames` steps: handle targets move
    linearly from their rest positions (weighted vertex combinations) to the pose."""
    tok = open(src).read().split()
    hdr = [int(t) for t in tok[:7]]
    nf, H, n, lists = hdr[0], hdr[1], hdr[2], hdr[3]
    if lists != 1 or any(hdr[4:]):
        raise RuntimeError(src + ": expected one recorded pose and no matrices")
    pos = 7
    weights = []
    for _ in range(H):
        weights.append(tok[pos:pos + n])
        pos += n
    target = [[float(x) for x in tok[pos + 3 * h:pos + 3 * h + 3]] for h in range(H)]
    V = read_off_vertices(rest_off)
    rest = []
    for h in range(H):
        p = [0.0, 0.0, 0.0]
        for i, w in enumerate(weights[h]):
            w = float(w)
            if w != 0.0:
                for k in range(3):
                    p[k] += w * V[i][k]
        rest.append(p)
    with open(dst, "w") as f:
        f.write("%d %d %d %d 0 0 0\n" % (frames, H, n, frames))
        for h in range(H):
            f.write(" ".join(weights[h]) + "\n")
        for fr in range(1, frames + 1):
            a = fr / frames
            for h in range(H):
                p = target[h] if fr == frames else [(1 - a) * rest[h][k] + a * target[h][k] for k in range(3)]
                f.write("%.17g %.17g %.17g\n" % tuple(p))


class Runner:
    def __init__(self, args):
        # A snapshot of the binary, so that a rebuild during the study does not mix two builds.
        with open(args.qpr, "rb") as f:
            self.qpr_hash = hashlib.sha256(f.read()).hexdigest()[:12]
        self.qpr = os.path.join(args.work, "qpr-" + self.qpr_hash)
        if not os.path.exists(self.qpr):
            shutil.copy2(args.qpr, self.qpr)
        self.work = args.work
        self.nice = args.nice
        self.resume = args.resume
        self.log = open(os.path.join(self.work, "study.log"), "a")
        self.count = 0
        self.kept = 0
        self.seconds = 0.0
        self.loads = []  # 1-minute load average when each run started
        self.loads_missing = 0

    def run(self, key, argv, env=None):
        """Runs `qpr ARGV` (serially), returns the parsed --report JSON."""
        report = os.path.join(self.work, key + ".json")
        cmdfile = os.path.join(self.work, key + ".cmd")
        full = (["env"] + ["%s=%s" % kv for kv in sorted((env or {}).items())] if env else []) + \
            ["nice", "-n", str(self.nice), self.qpr] + argv + ["--report", report]
        line = " ".join(shlex.quote(a) for a in full)
        if self.resume and os.path.exists(report) and os.path.exists(cmdfile) and \
                open(cmdfile).read().split("\n")[0] == line:
            print("  [kept] " + key, flush=True)
            self.count += 1
            self.kept += 1
            saved = open(cmdfile).read().split("\n")
            self.seconds += float(saved[1])
            if len(saved) > 2 and saved[2]:
                self.loads.append(float(saved[2]))
            else:
                self.loads_missing += 1
            return json.load(open(report))
        for p in (report, cmdfile):
            if os.path.exists(p):
                os.remove(p)
        t0 = time.time()
        load = os.getloadavg()[0]
        self.loads.append(load)
        print("  [run ] %-48s" % key, end="", flush=True)
        proc = subprocess.run(full, stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True)
        dt = time.time() - t0
        self.count += 1
        self.seconds += dt
        self.log.write("$ %s\n%s\n(%.1f s, exit %d)\n\n" % (line, proc.stdout, dt, proc.returncode))
        self.log.flush()
        print(" %6.1f s" % dt, flush=True)
        if proc.returncode != 0:
            raise RuntimeError("qpr failed (%s):\n%s" % (line, proc.stdout[-2000:]))
        open(cmdfile, "w").write("%s\n%.3f\n%.2f\n" % (line, dt, load))
        return json.load(open(report))


# ---------------------------------------------------------------------------
# Scenarios
# ---------------------------------------------------------------------------
class Study:
    def __init__(self, args, cfg):
        self.args = args
        self.cfg = cfg
        self.data = args.data
        self.bs = os.path.join(self.data, "meshes", "botsch-sorkine")
        self.work = args.work
        self.r = Runner(args)
        self.anim_files = {}
        self.failures = []
        self.results = {}

    def mesh(self, model):
        return os.path.join(self.bs, model + ".off")

    def scenario_args(self, kind, name, frames=None):
        """Handle-source arguments of `qpr deform`/`qpr compare` for a scenario."""
        frames = frames or self.cfg["frames"]
        if kind == "sel":
            s = os.path.join(self.bs, name)
            return [self.mesh(name), "--sel", s + ".sel", "--def", s + ".def", "--frames", str(frames)], name
        if kind == "tet":
            s = os.path.join(self.bs, dict(self.cfg["tet"])[name])
            return [os.path.join(self.data, "tets", name + ".node"), "--sel", s + ".sel", "--def", s + ".def",
                    "--frames", str(frames)], name
        model, pose = name.split("/")
        key = (name, frames)
        if key not in self.anim_files:
            dst = os.path.join(self.work, "anim_%s_%s_%d.anim" % (model, pose, frames))
            write_interpolated_anim(os.path.join(self.data, "paper-examples", model, pose + ".anim"),
                                    self.mesh(model), frames, dst)
            self.anim_files[key] = dst
        return [self.mesh(model), "--anim", self.anim_files[key]], model

    @staticmethod
    def tag(kind, name):
        return kind + "_" + name.replace("/", "_")

    def published_reference(self, kind, model):
        """The converged CGAL (surfaces) / libigl (tets) shape of a .sel/.def scenario, if there is one."""
        pattern = {"sel": "cgal_sr_%s_it*.off", "tet": "libigl_tet_%s_it*.off"}.get(kind)
        if not pattern:
            return None
        files = sorted(glob.glob(os.path.join(self.data, "references", pattern % model)))
        return files[-1] if files else None

    def lg_cap(self, model):
        caps = self.cfg["lg_rounds"]
        return caps.get(model, caps["default"])

    # -- main table: qpr compare against local-global classic ARAP --------------
    def main_table(self):
        rows = []
        scen = ([("sel", m) for m in self.cfg["selv"]] + [("tet", t) for t, _ in self.cfg["tet"]] +
                [("anim", "%s/%s" % a) for a in self.cfg["anim"]])
        for kind, name in scen:
            sargs, model = self.scenario_args(kind, name)
            tag = self.tag(kind, name)
            out = os.path.join(self.work, "cmp_" + tag)
            rep = self.r.run("compare_" + tag, ["compare"] + sargs + [
                "--reference", "local-global", "--reference-iterations", str(self.lg_cap(model)), "--out-dir", out])
            ref = rep["references"]["local-global"]
            row = dict(kind=kind, name=name, model=model, rep=rep, ref_mesh=ref["mesh"],
                       reduced_mesh=os.path.join(out, "reduced" + os.path.splitext(ref["mesh"])[1]))
            cg = self.published_reference(kind, model)
            if cg:
                diag = rep["bounding_box_diagonal"]
                C = read_off_vertices(cg)  # tets: the surface nodes, which come first
                row["cgal"] = os.path.basename(cg)
                row["rms_cgal"] = deviation(read_off_vertices(row["reduced_mesh"])[:len(C)], C, diag)
                row["lg_vs_cgal"] = deviation(read_off_vertices(row["ref_mesh"])[:len(C)], C, diag)
            rows.append(row)
        self.results["main"] = rows

    def reference_mesh(self, kind, name):
        for row in self.results["main"]:
            if row["kind"] == kind and row["name"] == name:
                return row
        raise KeyError(name)

    def ceres_table(self):
        rows = []
        for model, its in self.cfg["ceres"]:
            sargs, _ = self.scenario_args("sel", model)
            tag = self.tag("sel", model)
            out = os.path.join(self.work, "ceres_" + tag)
            rep = self.r.run("ceres_" + tag, ["compare"] + sargs + [
                "--reference", "ceres", "--reference-iterations", str(its), "--out-dir", out])
            c = rep["references"]["ceres"]
            main = self.reference_mesh("sel", model)
            diag = main["rep"]["bounding_box_diagonal"]
            row = dict(model=model, cap=its, rep=rep, ceres=c, lg=main["rep"]["references"]["local-global"])
            if "mesh" in c:
                row["ceres_vs_lg"] = deviation(read_off_vertices(c["mesh"]), read_off_vertices(main["ref_mesh"]), diag)
            rows.append(row)
        self.results["ceres"] = rows

    def ladder_table(self):
        """Local-global stopped after k rounds: how far from the capped run and from CGAL, at what cost."""
        rows = []
        for model, caps in self.cfg["ladder"]:
            sargs, _ = self.scenario_args("sel", model)
            main = self.reference_mesh("sel", model)
            diag = main["rep"]["bounding_box_diagonal"]
            final = read_off_vertices(main["ref_mesh"])
            cg = self.published_reference("sel", model)
            C = read_off_vertices(cg) if cg else None
            for k in caps:
                tag = "%s_%d" % (self.tag("sel", model), k)
                out = os.path.join(self.work, "ladder_" + tag)
                rep = self.r.run("ladder_" + tag, ["compare"] + sargs + [
                    "--reference", "local-global", "--reference-iterations", str(k), "--out-dir", out])
                V = read_off_vertices(rep["references"]["local-global"]["mesh"])
                rows.append(dict(model=model, rounds=k, rep=rep, main=main["rep"],
                                 vs_final=deviation(V, final, diag), vs_cgal=deviation(V, C, diag) if C else None))
        self.results["ladder"] = rows

    def modified_table(self):
        rows = []
        for kind, name, extra in self.cfg["modified"]:
            sargs, model = self.scenario_args(kind, name)
            opts = []
            for k, v in extra.items():
                opts += ["--" + k, str(v)]
            tag = self.tag(kind, name) + "".join("_%s%s" % (k[:3], v) for k, v in extra.items())
            out = os.path.join(self.work, "mod_" + tag)
            rep = self.r.run("modified_" + tag, ["compare"] + sargs + opts + [
                "--reference", "local-global", "--energy", "modified",
                "--reference-iterations", str(self.lg_cap(model)), "--out-dir", out])
            main = self.reference_mesh(kind, name)
            diag = main["rep"]["bounding_box_diagonal"]
            emin = read_off_vertices(rep["references"]["local-global"]["mesh"])
            classic = read_off_vertices(main["ref_mesh"])
            red = read_off_vertices(os.path.join(out, "reduced.off"))
            rows.append(dict(kind=kind, name=name, model=model, extra=extra, rep=rep,
                             emin_vs_classic=deviation(emin, classic, diag),
                             reduced_vs_classic=deviation(red, classic, diag),
                             reduced_vs_emin=deviation(red, emin, diag),
                             classic_energy=main["rep"]["references"]["local-global"]["arap_energy"]))
        self.results["modified"] = rows

    # -- sweeps: qpr deform, deviation from the scenario's classic reference ----
    def deform(self, kind, name, key, opts, frames=None, cache=None):
        sargs, model = self.scenario_args(kind, name, frames)
        out = os.path.join(self.work, key + ".off")
        argv = ["deform"] + sargs + opts + ["--out", out]
        if cache:
            argv += ["--cache", cache]
        rep = self.r.run(key, argv)
        main = self.reference_mesh(kind, name)
        diag = main["rep"]["bounding_box_diagonal"]
        ref = main["rep"]["references"]["local-global"]
        rms, mx = deviation(read_off_vertices(out), read_off_vertices(main["ref_mesh"]), diag)
        return dict(rep=rep, rms=rms, max=mx, ratio=rep["arap_energy"] / ref["arap_energy"],
                    speedup=ref["solve_ms"] / rep["frame_ms"])

    def sweep(self, what, option, values, scen):
        res = {}
        for kind, name in scen:
            pts = []
            for v in values:
                key = "%s_%s_%s" % (what, self.tag(kind, name), v)
                try:
                    r = self.deform(kind, name, key, ["--" + option, str(v)])
                except RuntimeError as e:  # a setting the deformer rejects is a result too
                    print("    failed: " + str(e).strip().splitlines()[-1])
                    self.failures.append((key, str(e).strip().splitlines()[-1]))
                    continue
                r["value"] = v
                pts.append(r)
            res[(kind, name)] = pts
        self.results[what] = res

    def paper_ids(self):
        rows = []
        for name, lin, rot in self.cfg["paper_ids"]:
            model = name.split("/")[0]
            d = os.path.join(self.data, "paper-examples", model)
            r = self.deform("anim", name, "paperids_" + self.tag("anim", name),
                            ["--linear-groups", os.path.join(d, lin), "--rotational-clusters", os.path.join(d, rot)])
            r.update(name=name, files="%s, %s" % (lin, rot))
            rows.append(r)
        self.results["paper_ids"] = rows

    def timing(self):
        """The frame time alone: 64 frames of the cached model, with the default threads and with one."""
        rows = []
        for model in self.cfg["timing"]:
            sargs, _ = self.scenario_args("sel", model, 64)
            cache = os.path.join(self.work, "cache_" + self.tag("sel", model) + ".qprc")
            main = self.reference_mesh("sel", model)
            for threads in (0, 1):
                env = {"OMP_NUM_THREADS": "1", "OPENBLAS_NUM_THREADS": "1"} if threads else None
                rep = self.r.run("timing_%s_t%d" % (self.tag("sel", model), threads),
                                 ["deform"] + sargs + ["--cache", cache], env=env)
                rows.append(dict(model=model, threads=threads, rep=rep, main=main["rep"]))
        self.results["timing"] = rows

    def convergence(self):
        res = {}
        for kind, name, extra in self.cfg["conv_scen"]:
            opts = []
            for k, v in extra.items():
                opts += ["--" + k, str(v)]
            label = self.tag(kind, name) + "".join("_%s%s" % (k[:3], v) for k, v in extra.items())
            cache = os.path.join(self.work, "cache_" + label + ".qprc")
            pts = []
            for it in self.cfg["conv_iters"]:
                for fr in self.cfg["conv_frames"]:
                    r = self.deform(kind, name, "conv_%s_f%d_i%d" % (label, fr, it),
                                    opts + ["--iterations", str(it)], frames=fr, cache=cache)
                    r.update(frames=fr, iterations=it)
                    pts.append(r)
            res[(kind, name, label)] = (extra, pts)
        self.results["conv"] = res


# ---------------------------------------------------------------------------
# Output: markdown fragments and the figures (matplotlib)
# ---------------------------------------------------------------------------
def arguments():
    """The command line."""
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--qpr", default=os.path.join(ROOT, "build", "bin", "qpr"))
    ap.add_argument("--data", default=os.path.join(os.path.dirname(ROOT), "shared", "data"))
    ap.add_argument("--work", default=None, help="work directory (default /tmp/qpreduce-quality[-quick])")
    ap.add_argument("--nice", type=int, default=10)
    ap.add_argument("--quick", action="store_true", help="smoke run: cylinder only, short settings, no docs")
    ap.add_argument("--resume", action="store_true", help="reuse runs whose command line is unchanged")
    ap.add_argument("--doc", default=os.path.join(ROOT, "docs", "quality.md"))
    ap.add_argument("--figures", default=None, help="figure directory (default docs/figures; quick: the work dir)")
    ap.add_argument("--skip", default="", help="comma list of parts to skip: ceres,ladder,modified,rot,lin,alpha,beta,paper,conv,timing")
    return ap.parse_args()


def run_info(args, cfg, st, t0, loads, wall):
    """The "run" table's rows: command, date, machine, load, qpr build, settings, runs."""
    load0, load1 = loads
    cpu = platform.processor() or ""
    try:
        for line in subprocess.run(["lscpu"], stdout=subprocess.PIPE, text=True).stdout.splitlines():
            if line.startswith("Model name:"):
                cpu = line.split(":", 1)[1].strip()
    except OSError:
        pass
    try:
        commit = subprocess.run(["git", "-C", ROOT, "rev-parse", "--short", "HEAD"], stdout=subprocess.PIPE,
                                text=True).stdout.strip()
    except OSError:
        commit = "?"
    info = [("command", "`python3 scripts/quality_study.py%s`" % (" --quick" if args.quick else "")),
            ("date (UTC)", time.strftime("%Y-%m-%d %H:%M", time.gmtime(t0))),
            ("machine", "%s, %d cores (`nproc`), runs serial under `nice -n %d`" % (cpu, os.cpu_count(), args.nice)),
            ("load average (1 min) when the runs started", "%.2f – %.2f (median %.2f)" % (
                min(st.r.loads), max(st.r.loads), sorted(st.r.loads)[len(st.r.loads) // 2])
             if st.r.loads else "not recorded for the reused runs (%d); %.2f / %.2f now" % (
                st.r.loads_missing, load0[0], load1[0])),
            ("qpr", "%s, built %s UTC (sha256 %s…; tree HEAD %s)" % (
                os.path.relpath(args.qpr, ROOT),
                time.strftime("%Y-%m-%d %H:%M", time.gmtime(os.path.getmtime(args.qpr))), st.r.qpr_hash, commit)),
            ("frames from rest to the pose", "%d (`.sel/.def` `--frames`; `.anim` poses interpolated linearly)"
             % cfg["frames"]),
            ("local-global caps (rounds)", ", ".join("%s %d" % kv for kv in cfg["lg_rounds"].items())),
            ("Ceres caps (LM iterations)", ", ".join("%s %d" % kv for kv in cfg["ceres"]) or "—"),
            ("qpr runs / their wall time", "%d / %.0f s%s" % (
                st.r.count, st.r.seconds,
                " (%d reused from an earlier invocation with --resume)" % st.r.kept if st.r.kept else
                " (%.0f s with the Python side)" % wall))]
    if st.failures:
        info.append(("runs qpr refused", "; ".join("`%s`: %s" % f for f in st.failures)))
    return info


def main():
    args = arguments()
    cfg = QUICK if args.quick else FULL
    args.work = args.work or ("/tmp/qpreduce-quality" + ("-quick" if args.quick else ""))
    os.makedirs(args.work, exist_ok=True)
    figdir = args.figures or (args.work if args.quick else os.path.join(ROOT, "docs", "figures"))
    skip = set(s for s in args.skip.split(",") if s)
    if not os.path.exists(args.qpr):
        sys.exit("no qpr at %s (build it, or pass --qpr)" % args.qpr)
    if not os.path.isdir(os.path.join(args.data, "meshes", "botsch-sorkine")):
        sys.exit("no shared data at %s (pass --data)" % args.data)

    t0 = time.time()
    load0 = os.getloadavg()
    st = Study(args, cfg)
    print("main table (qpr compare vs local-global classic ARAP)")
    st.main_table()
    parts = [("ceres", "Ceres", st.ceres_table),
             ("ladder", "local-global stopped early", st.ladder_table),
             ("modified", "E′ references (--energy modified)", st.modified_table),
             ("rot", "rotational proxy sweep",
              lambda: st.sweep("rot", "rotational-proxies", cfg["rot_sweep"], cfg["rot_scen"])),
             ("lin", "linear proxy sweep",
              lambda: st.sweep("lin", "linear-proxies", cfg["lin_sweep"], cfg["lin_scen"])),
             ("alpha", "α sweep", lambda: st.sweep("alpha", "alpha", cfg["alpha_sweep"], cfg["alpha_scen"])),
             ("beta", "β sweep", lambda: st.sweep("beta", "beta", cfg["beta_sweep"], cfg["beta_scen"])),
             ("paper", "the paper demo's proxies", st.paper_ids),
             ("conv", "frames × iterations", st.convergence),
             ("timing", "frame timing", st.timing)]
    for name, title, part in parts:
        if name not in skip:
            print(title)
            part()
    wall = time.time() - t0
    load1 = os.getloadavg()
    info = run_info(args, cfg, st, t0, (load0, load1), wall)
    frag = fragments(st, info)
    figs = figures(st, figdir)
    fragfile = os.path.join(args.work, "quality_fragments.md")
    with open(fragfile, "w") as f:
        for name, body in frag.items():
            f.write("<!-- quality_study:%s -->\n%s\n<!-- /quality_study:%s -->\n\n" % (name, body, name))
    json.dump({k: (v if isinstance(v, list) else {str(kk): vv for kk, vv in v.items()})
               for k, v in st.results.items()}, open(os.path.join(args.work, "results.json"), "w"),
              indent=1, default=str)
    print("fragments: %s" % fragfile)
    print("figures: %s" % ", ".join(figs))
    if not args.quick and os.path.exists(args.doc):
        missing = splice(args.doc, frag)
        print("updated %s%s" % (args.doc, (" (no markers for: %s)" % ", ".join(missing)) if missing else ""))
    print("%d qpr runs, %.0f s" % (st.r.count, wall))




if __name__ == "__main__":
    main()
