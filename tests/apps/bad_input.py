#!/usr/bin/env python3
"""Bad-input suite for the qpr command line (docs/robustness.md).

Every case runs qpr on a small input made here and asserts the exit code and
words of the message; the writer cases also assert that an earlier output
file is left intact and that no temporary file stays behind. Run:

    bad_input.py QPR_BINARY [--group NAME] [--list]

Groups: options, meshes, handles, scenes, check, matrix, writers, memory, view. Exit status 0 when
every case of the selected groups passed; a failing case prints its command,
exit code and stderr. The view group (the viewer's writers) needs a display:
without DISPLAY the suite runs itself again under `xvfb-run -a`; it is skipped,
saying so, when this qpr was built without the viewer.
"""
import argparse
import os
import re
import resource
import shutil
import signal
import subprocess
import sys
import tempfile
import time

# ---------------------------------------------------------------- inputs


def tube(rings=6, around=8):
    """An open tube (rings × around vertices) as OFF text, its .sel and a .def."""
    import math
    V, F = [], []
    for r in range(rings):
        for a in range(around):
            t = 2 * math.pi * a / around
            V.append((math.cos(t), math.sin(t), 0.8 * r))
    for r in range(rings - 1):
        for a in range(around):
            i, j = r * around + a, r * around + (a + 1) % around
            k, l = i + around, j + around
            F += [(i, j, l), (i, l, k)]
    off = "OFF\n%d %d 0\n" % (len(V), len(F))
    off += "".join("%g %g %g\n" % v for v in V)
    off += "".join("3 %d %d %d\n" % f for f in F)
    sel = "".join("%d\n" % (0 if v[2] < 0.1 else 2 if v[2] > 0.8 * (rings - 1) - 0.1 else 1) for v in V)
    return off, sel, len(V)


OFF, SEL, NV = tube()
DEF = "0 -1 0 0\n1 0 0 0\n0 0 1 0.5\n0 0 0 1\n"
OBJ = "".join("v " + " ".join(l.split()) + "\n" for l in OFF.splitlines()[2:2 + NV])
OBJ += "".join("f %d %d %d\n" % tuple(int(x) + 1 for x in l.split()[1:])
               for l in OFF.splitlines()[2 + NV:])
SMALL = ["--linear-proxies", "6", "--rotational-proxies", "4", "--frames", "1"]
NO_LINEAR = ["--rotational-proxies", "4", "--frames", "1"]
NO_ROTATIONAL = ["--linear-proxies", "6", "--frames", "1"]

# A tiny QP: H = I (4×4), C = e1, one demand x2 = 1.
H = "%%MatrixMarket matrix coordinate real symmetric\n4 4 4\n1 1 1\n2 2 1\n3 3 1\n4 4 1\n"
C = "%%MatrixMarket matrix coordinate real general\n4 1 1\n1 1 1\n"
A = "%%MatrixMarket matrix coordinate real general\n4 1 1\n2 1 1\n"
B = "%%MatrixMarket matrix array real general\n1 1\n1\n"


def base_files():
    return {
        "tube.off": OFF, "tube.sel": SEL, "tube.def": DEF, "tube.obj": OBJ,
        "H.mtx": H, "C.mtx": C, "dem/A_d0.mtx": A, "dem/b_d0.mtx": B,
    }


def deform(*extra, mesh="{W}/tube.off", small=SMALL):
    return ["deform", mesh, "--sel", "{W}/tube.sel", "--def", "{W}/tube.def"] + small + list(extra)


def qp(*extra, H="{W}/H.mtx", demands="{W}/dem"):
    return ["qp", "--H", H, "--C", "{W}/C.mtx", "--demands", demands] + list(extra)


def scene(body):
    """A JSON scene on tube.off; `body` is the text after the mesh entry."""
    return '{"mesh": "tube.off"' + body + "}"


# ---------------------------------------------------------------- cases

CASES = []


def case(group, name, args, code, words, files=None, max_seconds=None, stdout_words=None, stderr_absent=None):
    CASES.append(dict(group=group, name=name, args=args, code=code, words=words, files=files or {},
                      max_seconds=max_seconds, stdout_words=stdout_words or [], stderr_absent=stderr_absent or []))


OPT = 105  # CLI11's exit code for a value that fails its check
RUN = 2    # qpr's exit code for bad input found while running

# Options: every numeric option refuses NaN, infinities, out-of-range values,
# with the rule in words.
case("options", "theorem --trials 0", ["theorem", "--trials", "0"], OPT, ["--trials", "whole number from 1 to"])
case("options", "theorem --trials 1e8 (was bad_alloc)", ["theorem", "--trials", "100000000"], OPT,
     ["--trials", "from 1 to 1000000"])
case("options", "theorem --trials -3", ["theorem", "--trials", "-3"], OPT, ["--trials", "got '-3'"])
case("options", "theorem --trials abc", ["theorem", "--trials", "abc"], OPT, ["--trials", "got 'abc'"])
case("options", "theorem --trials 2.5", ["theorem", "--trials", "2.5"], OPT, ["--trials", "whole number"])
case("options", "theorem --seed -1 (was 2^64-1)", ["theorem", "--seed", "-1"], OPT, ["--seed", "got '-1'"])
case("options", "theorem --seed 2^64", ["theorem", "--seed", "18446744073709551616"], OPT, ["--seed"])
case("options", "theorem --trials with a 100 kB token", ["theorem", "--trials", "9" * 100000], OPT,
     ["--trials", "(100000 characters)"])
case("options", "qp --soft nan (was a silent hard solve)", qp("--soft", "nan"), OPT, ["--soft", "NaN"])
case("options", "qp --soft inf", qp("--soft", "inf"), OPT, ["--soft", "finite"])
case("options", "qp --soft 0", qp("--soft", "0"), OPT, ["--soft", "greater than 0"])
case("options", "qp --soft -1", qp("--soft", "-1"), OPT, ["--soft", "greater than 0"])
case("options", "qp --soft 1e400", qp("--soft", "1e400"), OPT, ["--soft", "finite"])
case("options", "deform --alpha nan", deform("--alpha", "nan"), OPT, ["--alpha", "NaN"])
case("options", "deform --alpha 1e308 (was 'contains NaN')", deform("--alpha", "1e308"), OPT,
     ["--alpha", "between 0 and 1e+12"])
case("options", "deform --alpha -1", deform("--alpha", "-1"), OPT, ["--alpha", "between 0 and"])
case("options", "deform --beta inf", deform("--beta", "inf"), OPT, ["--beta", "finite"])
case("options", "deform --gamma -0.5", deform("--gamma", "-0.5"), OPT, ["--gamma", "between 0 and"])
case("options", "deform --psi 1", deform("--model", "conformal", "--psi", "1"), OPT, ["--psi", "greater than 1"])
case("options", "deform --psi nan", deform("--model", "conformal", "--psi", "nan"), OPT, ["--psi", "NaN"])
case("options", "deform --tolerance 2", deform("--tolerance", "2"), OPT, ["--tolerance", "between 0 and 1"])
case("options", "deform --tolerance nan", deform("--tolerance", "nan"), OPT, ["--tolerance", "NaN"])
case("options", "deform --iterations 0", deform("--iterations", "0"), OPT, ["--iterations", "from 1 to"])
case("options", "deform --anderson 17", deform("--anderson", "17"), OPT, ["--anderson", "from 0 to 16"])
case("options", "deform --frames 0", deform("--frames", "0"), OPT, ["--frames", "from 1 to"])
case("options", "deform --linear-proxies 0", deform("--linear-proxies", "0"), OPT, ["--linear-proxies"])
case("options", "deform --soft nan", deform("--soft", "nan"), OPT, ["--soft", "NaN"])
case("options", "demo --frames 0", ["demo", "--frames", "0"], OPT, ["--frames", "from 1 to 10000"])
case("options", "demo --iterations 1001", ["demo", "--iterations", "1001"], OPT, ["--iterations", "from 1 to 1000"])
case("options", "qp --theorem-max-n -5 (was accepted silently)", qp("--theorem-max-n", "-5"), OPT,
     ["--theorem-max-n", "whole number from 0 to 100000", "got '-5'"])
case("options", "deform --refine-anderson 99 without --refine (was accepted)", deform("--refine-anderson", "99"), OPT,
     ["--refine-anderson", "whole number from 1 to 16", "got '99'"])
case("options", "compare --refine-anderson 0", ["compare", "{W}/tube.off", "--refine-anderson", "0"], OPT,
     ["--refine-anderson", "whole number from 1 to 16"])
case("options", "compare --convergence-tolerance -1 (was accepted)", ["compare", "{W}/tube.off",
     "--convergence-tolerance", "-1"], OPT, ["--convergence-tolerance", "between 0 and 1"])
case("options", "deform --refine=-1", deform("--refine=-1"), OPT, ["--refine", "D must be a finite number ≥ 0"])
case("options", "deform --refine=nan", deform("--refine=nan"), OPT, ["--refine", "D must be a finite number ≥ 0"])
case("options", "deform --cold-start-rounds -1", deform("--cold-start-rounds", "-1"), OPT,
     ["--cold-start-rounds", "whole number from 0 to 100000"])
case("options", "deform --rotational-proxies 1e3x", deform("--rotational-proxies", "1e3x"), OPT,
     ["--rotational-proxies", "got '1e3x'"])

# Mesh files: each refused with the file, the line where there is one, and the problem.
BOM = "\ufeff"
case("meshes", "OFF: empty file", deform(mesh="{W}/m.off"), RUN, ["m.off", "empty file"], {"m.off": ""})
case("meshes", "OFF: wrong keyword", deform(mesh="{W}/m.off"), RUN, ["m.off:1", "not an OFF file"],
     {"m.off": "PLY\n3 1 0\n"})
case("meshes", "OFF: keyword after a BOM is read", deform("--out", "{W}/bom_out.off", mesh="{W}/m.off"), 0, [],
     {"m.off": BOM + OFF})
case("meshes", "OFF: a BOM elsewhere is shown, not invisible", deform(mesh="{W}/m.off"), RUN,
     ["\\xEF\\xBB\\xBF"], {"m.off": OFF.replace("\n1 0 0\n", "\n" + BOM + "1 0 0\n", 1)})
case("meshes", "OFF: 2^31 vertices in a tiny file", deform(mesh="{W}/m.off"), RUN, ["m.off", "end of file"],
     {"m.off": "OFF\n2147483648 1 0\n0 0 0\n"}, max_seconds=5)
case("meshes", "OFF: negative count", deform(mesh="{W}/m.off"), RUN, ["m.off", "negative"],
     {"m.off": "OFF\n-3 1 0\n"})
case("meshes", "OFF: NaN coordinate", deform(mesh="{W}/m.off"), RUN, ["m.off", "non-finite", "nan"],
     {"m.off": OFF.replace("\n1 0 0\n", "\nnan 0 0\n", 1)})
case("meshes", "OFF: overflowing coordinate", deform(mesh="{W}/m.off"), RUN, ["m.off", "out of the range"],
     {"m.off": OFF.replace("\n1 0 0\n", "\n1e999 0 0\n", 1)})
case("meshes", "OFF: index out of range", deform(mesh="{W}/m.off"), RUN, ["m.off", "vertex index 999 out of range"],
     {"m.off": OFF.replace("3 0 1 9", "3 0 1 999", 1)})
case("meshes", "OFF: face with 2 corners", deform(mesh="{W}/m.off"), RUN, ["m.off", "2 corner"],
     {"m.off": OFF.replace("3 0 1 9", "2 0 1", 1)})
case("meshes", "OFF: 1 MB token is cut in the message", deform(mesh="{W}/m.off"), RUN,
     ["m.off", "…' (1048577 bytes)"], {"m.off": OFF.replace("\n1 0 0\n", "\n" + "7" * 1048576 + "x 0 0\n", 1)})
case("meshes", "OFF: data after the last face", deform(mesh="{W}/m.off"), RUN, ["m.off"],
     {"m.off": OFF + "3 0 1 2\n"})
case("meshes", "OBJ: index 0", deform(mesh="{W}/m.obj"), RUN, ["m.obj", "0"],
     {"m.obj": OBJ.replace("f 1 2 10", "f 0 2 10", 1)})
case("meshes", "OBJ: malformed number", deform(mesh="{W}/m.obj"), RUN, ["m.obj", "malformed number '1.0.0'"],
     {"m.obj": OBJ.replace("v 1 0 0", "v 1.0.0 0 0", 1)})
case("meshes", "OBJ: no faces", deform(mesh="{W}/m.obj"), RUN, ["m.obj", "no faces"], {"m.obj": "v 0 0 0\n"})
case("meshes", "PLY: unknown format", deform(mesh="{W}/m.ply"), RUN, ["m.ply", "unknown PLY format 'ascii2'"],
     {"m.ply": "ply\nformat ascii2 1.0\nend_header\n"})
case("meshes", "PLY: big-endian", deform(mesh="{W}/m.ply"), RUN, ["m.ply", "big"],
     {"m.ply": "ply\nformat binary_big_endian 1.0\nelement vertex 1\nproperty float x\nend_header\n"})
case("meshes", "PLY: binary with 2^31 vertices in a tiny file", deform(mesh="{W}/m.ply"), RUN, ["m.ply"],
     {"m.ply": "ply\nformat binary_little_endian 1.0\nelement vertex 2147483647\nproperty float x\nproperty float y\n"
               "property float z\nelement face 1\nproperty list uchar int vertex_indices\nend_header\n\0\0\0\0"},
     max_seconds=5)
case("meshes", "PLY: unknown property type", deform(mesh="{W}/m.ply"), RUN, ["m.ply", "property type 'quad'"],
     {"m.ply": "ply\nformat ascii 1.0\nelement vertex 1\nproperty quad x\nend_header\n"})
case("meshes", "MEDIT: unknown section", deform(mesh="{W}/m.mesh"), RUN, ["m.mesh", "unknown MEDIT section"],
     {"m.mesh": "MeshVersionFormatted 1\nDimension 3\nWhatever 3\nEnd\n"})
case("meshes", "MEDIT: 2^40 vertices in a tiny file", deform(mesh="{W}/m.mesh"), RUN, ["m.mesh"],
     {"m.mesh": "MeshVersionFormatted 1\nDimension 3\nVertices\n1099511627776\n0 0 0 0\nEnd\n"}, max_seconds=5)
case("meshes", "TetGen: .node with a huge count", deform(mesh="{W}/m.node"), RUN, ["m.node"],
     {"m.node": "4000000000 3 0 0\n1 0 0 0\n", "m.ele": "1 4 0\n1 1 2 3 4\n"}, max_seconds=5)
FAR = OFF.replace("OFF\n%d " % NV, "OFF\n%d " % (NV + 1), 1).replace(
    "\n3 ", "\n1e300 1e300 1e300\n3 ", 1)
case("meshes", "a far-away unreferenced vertex (was 'contains NaN' at write time)",
     ["deform", "{W}/far.off", "--sel", "{W}/far.sel", "--def", "{W}/tube.def", "--out", "{W}/o.off"] + SMALL,
     RUN, ["far.off", "vertex 48 at (1e+300", "overflow"], {"far.off": FAR, "far.sel": SEL + "1\n"})
TWO_V = OFF.splitlines()[2:2 + NV]
TWO_F = OFF.splitlines()[2 + NV:]
TWO = "OFF\n%d %d 0\n" % (2 * NV, 2 * len(TWO_F)) + "\n".join(
    TWO_V + [" ".join(str(float(x) + 10) for x in v.split()) for v in TWO_V] + TWO_F +
    ["3 " + " ".join(str(int(x) + NV) for x in f.split()[1:]) for f in TWO_F]) + "\n"
case("meshes", "a vertex at 1e200 (was 'contains NaN' at write time)",
     ["deform", "{W}/far.off", "--sel", "{W}/far.sel", "--def", "{W}/tube.def", "--out", "{W}/o.off"] + SMALL,
     RUN, ["far.off", "vertex 48 at (1e+200", "beyond 1e+100"], {"far.off": FAR.replace("1e300", "1e200"),
                                                                 "far.sel": SEL + "1\n"})
case("meshes", "an unreferenced vertex at 1e20 is named (was a silent run, every bbox-relative scale off)",
     ["deform", "{W}/far.off", "--sel", "{W}/far.sel", "--def", "{W}/tube.def", "--out", "{W}/o.off"] + SMALL,
     RUN, ["far.off", "vertex 48 is referenced by no element and lies 3.5e+19 bounding-box diagonals away"],
     {"far.off": FAR.replace("1e300", "1e20"), "far.sel": SEL + "1\n"})

def tube_with(vertices, faces, name="m.off"):
    """Files for the tube with extra vertices (numbered from NV) and faces ("a b c", 0-based): the mesh
    as `name`, and tube.sel with the extra vertices free."""
    lines = OFF.splitlines()[2:]
    V, F = lines[:NV] + list(vertices), lines[NV:] + ["3 " + f for f in faces]
    return {name: "OFF\n%d %d 0\n" % (len(V), len(F)) + "\n".join(V + F) + "\n",
            "tube.sel": SEL + "1\n" * len(vertices)}


case("meshes", "an unanchored component is named (was 'condition inf')",
     ["deform", "{W}/two.off", "--sel", "{W}/two.sel", "--def", "{W}/tube.def"] + SMALL, RUN,
     ["two.off", "connected component 1 (48 vertices, first vertex 48)", "no handle or fixed region anchoring it"],
     {"two.off": TWO, "two.sel": SEL + "1\n" * NV})
# The mesh pre-flight of `qpr deform` (diagnose_mesh, as `qpr check`): the named problem, not a symptom.
case("meshes", "pre-flight: a zero-area triangle is named with the file (was named by spokes_and_rims_elements)",
     deform(mesh="{W}/m.off"), RUN, ["m.off: triangle 80 (vertices 0, 48, 1) is degenerate: area"],
     tube_with(["0.8535535 0.3535535 0"], ["0 48 1"]))
case("meshes", "pre-flight: a near-degenerate triangle is a warning, the run goes on (was silent)",
     deform(mesh="{W}/m.off"), 0, ["warning", "m.off: triangle 80 (vertices 0, 48, 1) is nearly degenerate"],
     tube_with(["0.8535535 0.3535635 0"], ["0 48 1"]))
case("meshes", "pre-flight: a near-degenerate triangle with --strict is an error",
     deform("--strict", mesh="{W}/m.off"), RUN, ["(--strict) triangle 80 (vertices 0, 48, 1) is nearly degenerate"],
     tube_with(["0.8535535 0.3535635 0"], ["0 48 1"]))
case("meshes", "pre-flight: an unreferenced vertex inside the box is a warning",
     ["deform", "{W}/far.off", "--sel", "{W}/far.sel", "--def", "{W}/tube.def"] + SMALL, 0,
     ["warning", "vertex 48 is referenced by no element: it stays where it is"],
     {"far.off": FAR.replace("1e300 1e300 1e300", "0 0 2"), "far.sel": SEL + "1\n"})
case("meshes", "pre-flight: an unreferenced vertex 2 diagonals away is an error",
     ["deform", "{W}/far.off", "--sel", "{W}/far.sel", "--def", "{W}/tube.def"] + SMALL, RUN,
     ["vertex 48 is referenced by no element and lies 2 bounding-box diagonals away"],
     {"far.off": FAR.replace("1e300 1e300 1e300", "0 0 13.798"), "far.sel": SEL + "1\n"})
case("meshes", "pre-flight: two problems, the first named and the other counted",
     deform(mesh="{W}/m.off"), RUN, ["triangle 80 (vertices 0, 48, 1) is degenerate", "(and 1 more problem"],
     tube_with(["0.8535535 0.3535535 0", "0 0 1.5"], ["0 48 1"]))
case("meshes", "missing mesh file", deform(mesh="{W}/none.off"), RUN, ["none.off", "cannot open"])
case("meshes", "a directory as the mesh", deform(mesh="{W}/dem"), RUN, ["dem", "unsupported"])

# Handle files.
case("handles", ".sel: wrong count", deform(), RUN, ["tube.sel", "expected %d entries" % NV],
     {"tube.sel": SEL + "1\n"})
case("handles", ".sel: value 3", deform(), RUN, ["tube.sel", "3"], {"tube.sel": "3\n" + SEL.split("\n", 1)[1]})
case("handles", ".sel: no handle", deform(), RUN, ["handle"], {"tube.sel": SEL.replace("2", "1")})
case("handles", ".def: 3 rows", deform(), RUN, ["tube.def"], {"tube.def": "1 0 0 0\n0 1 0 0\n0 0 1 0\n"})
case("handles", ".def: NaN entry", deform(), RUN, ["tube.def", "nan"], {"tube.def": DEF.replace("0.5", "nan")})
case("handles", ".def: overflowing entry (was 'contains NaN')", deform(), RUN, ["tube.def", "1e400"],
     {"tube.def": DEF.replace("0.5", "1e400")})
case("handles", ".def: a translation of 1e300 (was 'contains NaN' in the engine)", deform(), RUN,
     ["frame 0", "patch 1's transform reaches", "bounding-box diagonals", "overflow"],
     {"tube.def": DEF.replace("0.5", "1e300")})
case("handles", ".def: a translation of 1e40 (was NaN in the engine)", deform(), RUN,
     ["frame 0", "patch 1's transform reaches", "beyond 1e+30 diagonals"], {"tube.def": DEF.replace("0.5", "1e40")})
case("handles", ".def: a scale of 1e200", deform(), RUN, ["frame 0", "reaches", "overflow"],
     {"tube.def": "1e200 0 0 0\n0 1e200 0 0\n0 0 1e200 0\n0 0 0 1\n"})
case("handles", ".def: extra data", deform(), RUN, ["tube.def", "unexpected data"], {"tube.def": DEF + "7\n"})
case("handles", ".id: negative group for linear proxies", deform("--linear-groups", "{W}/g.id", small=NO_LINEAR), RUN,
     ["g.id", "vertex 0 has id -1", "must be >= 0"], {"g.id": "-1\n" * NV})
case("handles", ".id: wrong count", deform("--rotational-clusters", "{W}/g.id", small=NO_ROTATIONAL), RUN, ["g.id", "expected"],
     {"g.id": "0\n" * (NV - 1)})
case("handles", ".anim: negative header count", ["deform", "{W}/tube.off", "--anim", "{W}/a.anim"] + SMALL[:4],
     RUN, ["a.anim", "negative"], {"a.anim": "1 -1 %d 1 0 0 0\n" % NV})
case("handles", ".anim: weights_per_handle not the vertex count", ["deform", "{W}/tube.off", "--anim", "{W}/a.anim"]
     + SMALL[:4], RUN, ["a.anim"], {"a.anim": "1 1 3 1 0 0 0\n1 0 0\n0 0 0\n"})

# JSON scenes.
case("scenes", "syntax error", ["deform", "--scene", "{W}/s.json"], RUN, ["s.json", "syntax"],
     {"s.json": '{"mesh": "tube.off",}'})
case("scenes", "duplicate key", ["deform", "--scene", "{W}/s.json"], RUN, ["s.json", "duplicate key", "mesh"],
     {"s.json": '{"mesh": "tube.off", "mesh": "other.off"}'})
case("scenes", "unknown key", ["deform", "--scene", "{W}/s.json"], RUN, ["s.json", "unknown key 'meshes'"],
     {"s.json": '{"mesh": "tube.off", "meshes": 1}'})
case("scenes", "a number too large for a double", ["deform", "--scene", "{W}/s.json"], RUN,
     ["s.json", "out of range", "number overflow"], {"s.json": scene(', "energy": {"alpha": 1e400}')})
case("scenes", "vertex out of range", ["deform", "--scene", "{W}/s.json"], RUN, ["s.json", "out of range"],
     {"s.json": scene(', "handles": [{"vertices": [9999], "targets": [[[0, 0, 0]]]}]')})
case("scenes", "missing mesh file", ["deform", "--scene", "{W}/s.json"], RUN, ["none.off"],
     {"s.json": '{"mesh": "none.off"}'})
case("scenes", "BOM before the object is read", ["deform", "--scene", "{W}/s.json", "--frames", "1"], RUN,
     ["s.json"], {"s.json": BOM + '{"mesh": "tube.off", "meshes": 1}'})

# Handles that cannot all hold, proxies the scene asks for.
PATCH = '"patches": [{"type": "fixed", "vertices": [0, 1, 2, 3, 4, 5, 6, 7]}]'
TWICE = ', %s, "handles": [{"vertices": [44], "targets": [[[1, 0, 5]]]}, {"vertices": [44], "targets": [[[3, 0, 5]]]}]'
case("scenes", "a vertex held at two places", ["deform", "--scene", "{W}/s.json"], RUN,
     ["s.json", "vertex 44 is held at two places", "point handles 0 and 1", "bounding-box diagonals apart"],
     {"s.json": scene(TWICE % PATCH)})
case("scenes", "a fixed vertex moved by a handle", ["deform", "--scene", "{W}/s.json"], RUN,
     ["s.json", "vertex 3 is in fixed patch 0", "point handle 0 moves it"],
     {"s.json": scene(', %s, "handles": [{"vertices": [3], "targets": [[[1, 0, 5]]]}]' % PATCH)})
case("scenes", "a group handle with all-zero weights", ["deform", "--scene", "{W}/s.json"], RUN,
     ["s.json", "/handles/0/group", "every weight is 0"],
     {"s.json": scene(', %s, "handles": [{"group": [[44, 0], [45, 0.0]], "targets": [[[1, 0, 5]]]}]' % PATCH)})
case("scenes", "an affine patch count", ["deform", "--scene", "{W}/s.json"], RUN,
     ["s.json", "/proxies/affine", "an .id file, not a count"],
     {"s.json": scene(', "proxies": {"affine": 3}, %s' % PATCH)})
case("scenes", "proxy counts are used (were ignored)", ["deform", "--scene", "{W}/s.json"], 0, [],
     {"s.json": scene(', "proxies": {"linear": 9, "rotational": 3}, %s, "handles": [{"vertices": [44], '
                      '"targets": [[[1, 0, 5]]]}]' % PATCH)}, stdout_words=["7 linear / 3 rotational proxies"])
HELD = ', "proxies": {"linear": 9}, %s, "handles": [{"vertices": [40, 41, 42, 43, 44, 45, 46, 47], "targets": [[%s]]}]' % (
    PATCH, ", ".join("[%d, %d, 9]" % (i % 3, i % 2) for i in range(8)))
case("scenes", "handles the subspace cannot meet are a warning (soft)", ["deform", "--scene", "{W}/s.json"], 0,
     ["warning", "cannot meet these handles", "rank 36 in the full space but 33", "soft constraints"],
     {"s.json": scene(HELD)})
case("scenes", "handles the subspace cannot meet say what makes them exact", ["deform", "--scene", "{W}/s.json"], 0,
     ["--exact-handles", "the handles end up to", "of the bounding-box diagonal from their targets"],
     {"s.json": scene(HELD)})
case("scenes", "--exact-handles meets them (their vertices are proxies)",
     ["deform", "--scene", "{W}/s.json", "--exact-handles"], 0, [], {"s.json": scene(HELD)},
     stdout_words=["handle residual"], stderr_absent=["warning"])
case("scenes", "--exact-handles refuses a group handle", ["deform", "--scene", "{W}/s.json", "--exact-handles"], RUN,
     ["point handle 0 is a group of 2 vertices", "as a patch"],
     {"s.json": scene(', %s, "handles": [{"group": [[44, 0.5], [45, 0.5]], "targets": [[1, 0, 5]]}]' % PATCH)})
case("scenes", "least-squares handles are a warning", ["deform", "--scene", "{W}/s.json", "--exact-unreachable"], 0,
     ["warning", "least-squares sense"], {"s.json": scene(HELD)})
case("scenes", "least-squares handles with --strict are an error", ["deform", "--scene", "{W}/s.json", "--strict"],
     RUN, ["exact handles were asked for (strict)", "constraints-least-squares"], {"s.json": scene(HELD)})

# `qpr check`: every finding on stdout, exit 0 clean, 1 warnings only, 2 errors (or warnings with --strict).
CLEAN, WARNINGS, ERRORS = 0, 1, 2
MEDIT_TETS = ("MeshVersionFormatted 1\nDimension 3\nVertices\n5\n0 0 0 0\n1 0 0 0\n0 1 0 0\n0 0 1 0\n0 0 -1 0\n"
              "Tetrahedra\n2\n1 2 3 4 0\n%s 0\nEnd\n")


def check(*extra, mesh="{W}/tube.off"):
    return ["check", mesh] + list(extra)


case("check", "a clean tube", check(), CLEAN, [], stdout_words=["48 vertices, 80 triangles, 1 connected component",
                                                                 "anchors: not checked", "status: clean"])
case("check", "a clean tube with its selection", check("--sel", "{W}/tube.sel"), CLEAN, [],
     stdout_words=["anchors: from", "tube.sel", "diagonal 4.899", "status: clean"])
case("check", "a zero-area triangle", check(mesh="{W}/m.off"), ERRORS, [],
     tube_with(["0.8535535 0.3535535 0"], ["0 48 1"]),
     stdout_words=["error: triangle 80 (vertices 0, 48, 1) is degenerate", "status: errors"])
case("check", "a sliver triangle", check(mesh="{W}/m.off"), WARNINGS, [],
     tube_with(["0.8535535 0.3535635 0"], ["0 48 1"]),
     stdout_words=["warning: triangle 80 (vertices 0, 48, 1) is nearly degenerate: quality 5.8e-06", "status: warnings"])
case("check", "a sliver triangle with --strict", check("--strict", mesh="{W}/m.off"), ERRORS, [],
     tube_with(["0.8535535 0.3535635 0"], ["0 48 1"]),
     stdout_words=["error: triangle 80", "status: errors (--strict: warnings are errors)"])
case("check", "a duplicate vertex (a seam)", check(mesh="{W}/m.off"), WARNINGS, [],
     tube_with(["1 0 0", "1 0 0.8", "0.707107 0.707107 0.8"], ["48 50 49"]),
     stdout_words=["vertex 48 lies at the position of vertex 0", "(3 vertices in all)"])
case("check", "an unreferenced vertex far away", check(mesh="{W}/m.off"), ERRORS, [], tube_with(["0 0 13.798"], []),
     stdout_words=["error: vertex 48 is referenced by no element and lies 2 bounding-box diagonals away"])
case("check", "an unreferenced vertex inside the box", check(mesh="{W}/m.off"), WARNINGS, [],
     tube_with(["0 0 2"], []), stdout_words=["warning: vertex 48 is referenced by no element"])
case("check", "an edge in three triangles", check(mesh="{W}/m.off"), WARNINGS, [], tube_with(["0 0 0.4"], ["8 9 48"]),
     stdout_words=["warning: edge (8, 9) is shared by 3 triangles"])
case("check", "a bow-tie vertex", check(mesh="{W}/m.off"), WARNINGS, [],
     tube_with(["2 0 -1", "2 1 -1"], ["0 48 49"]), stdout_words=["warning: vertex 0 joins 2 separate fans"])
case("check", "an unanchored component with --sel", check("--sel", "{W}/two.sel", mesh="{W}/two.off"), ERRORS, [],
     {"two.off": TWO, "two.sel": SEL + "1\n" * NV},
     stdout_words=["2 connected components", "connected component 1 (48 vertices, first vertex 48) has no handle or "
                   "fixed region anchoring it"])



def tube_flipped(every):
    """The tube with every `every`-th triangle (from triangle 1) flipped, as m.off."""
    lines = OFF.splitlines()
    faces = lines[2 + NV:]
    for f in range(1, len(faces), every):
        _, a, b, c = faces[f].split()
        faces[f] = "3 %s %s %s" % (a, c, b)
    return {"m.off": "\n".join(lines[:2 + NV] + faces) + "\n"}


# Triangles oriented against their neighbours (was clean).
case("check", "half the triangles flipped", check(mesh="{W}/m.off"), WARNINGS, [], tube_flipped(2),
     stdout_words=["warning: triangle 1 (vertices", "is oriented against the rest of its surface",
                   "(40 triangles in all)", "status: warnings"])
case("check", "one triangle flipped", check(mesh="{W}/m.off"), WARNINGS, [], tube_flipped(1000),
     stdout_words=["warning: triangle 1 (vertices", "3 of the 112 shared edges disagree"])
case("check", "flipped triangles with deform: a pre-flight warning", deform(mesh="{W}/m.off"), 0,
     ["warning:", "m.off", "oriented against the rest of its surface"], tube_flipped(2))


def two_anim(second):
    """An .anim for TWO: handle 0 at vertex 0, handle 1 at vertex `second`, one pose."""
    rows = []
    for v in (0, second):
        w = ["0"] * (2 * NV)
        w[v] = "1"
        rows.append(" ".join(w))
    return "1 2 %d 1 0 0 0\n%s\n0 0 0\n1 0 0\n" % (2 * NV, "\n".join(rows))


case("check", "an unanchored component with --anim", check("--anim", "{W}/two.anim", mesh="{W}/two.off"), ERRORS,
     [], {"two.off": TWO, "two.anim": two_anim(1)},
     stdout_words=["anchors: from", "two.anim", "connected component 1 (48 vertices, first vertex 48) has no handle"])
case("check", "both components held by --anim handles", check("--anim", "{W}/two.anim", mesh="{W}/two.off"), CLEAN,
     [], {"two.off": TWO, "two.anim": two_anim(NV)}, stdout_words=["2 connected components", "status: clean"])
case("check", "--sel and --anim together are refused",
     check("--sel", "{W}/tube.sel", "--anim", "{W}/a.anim"), ERRORS, ["give one of --sel, --anim and --scene"],
     {"a.anim": "1 1 %d 1 0 0 0\n1%s\n0 0 0\n" % (NV, " 0" * (NV - 1))})
case("check", "two components without anchors are clean", check(mesh="{W}/two.off"), CLEAN, [], {"two.off": TWO},
     stdout_words=["2 connected components", "status: clean"])
case("check", "an inverted tet", check(mesh="{W}/t.mesh"), WARNINGS, [], {"t.mesh": MEDIT_TETS % "1 2 3 5"},
     stdout_words=["2 tets", "warning: tet 1 is inverted", "1 of the 2 tets are positive"])
case("check", "every tet inverted", check(mesh="{W}/t.mesh"), WARNINGS, [],
     {"t.mesh": MEDIT_TETS.replace("1 2 3 4 0", "1 3 2 4 0") % "1 2 3 5"},
     stdout_words=["every tet is negatively oriented"])
case("check", "positive tets are clean", check(mesh="{W}/t.mesh"), CLEAN, [], {"t.mesh": MEDIT_TETS % "1 3 2 5"},
     stdout_words=["status: clean"])
# Two tets touching only at vertex 0 (MEDIT is 1-based): a non-manifold vertex of the solid.
PINCHED_TETS = ("MeshVersionFormatted 1\nDimension 3\nVertices\n7\n0 0 0 0\n1 0 0 0\n0 1 0 0\n0 0 1 0\n-1 0 0 0\n"
                "0 -1 0 0\n0 0 -1 0\nTetrahedra\n2\n1 2 3 4 0\n1 6 5 7 0\nEnd\n")
case("check", "two tets touching at one vertex", check(mesh="{W}/t.mesh"), WARNINGS, [], {"t.mesh": PINCHED_TETS},
     stdout_words=["7 vertices, 2 tets, 1 connected component",
                   "warning: vertex 0 joins 2 separate groups of tets", "the solid is not a manifold there",
                   "status: warnings"])
case("check", "two tets touching at one vertex with --strict", check("--strict", mesh="{W}/t.mesh"), ERRORS, [],
     {"t.mesh": PINCHED_TETS}, stdout_words=["error: vertex 0 joins 2 separate groups of tets", "status: errors"])
case("check", "a scene: its mesh and anchors", ["check", "--scene", "{W}/s.json"], CLEAN, [],
     {"s.json": scene(', %s, "handles": [{"vertices": [44], "targets": [[[1, 0, 5]]]}]' % PATCH)},
     stdout_words=["anchors: from", "s.json", "status: clean"])
case("check", "a scene that names another mesh than MESH", ["check", "{W}/tube.obj", "--scene", "{W}/s.json"], RUN,
     ["s.json names the mesh", "tube.off, not", "tube.obj"], {"s.json": scene(', ' + PATCH)})
case("check", "--sel and --scene together", check("--sel", "{W}/tube.sel", "--scene", "{W}/s.json"), RUN,
     ["give one of --sel, --anim and --scene, not several"], {"s.json": scene(', ' + PATCH)})
case("check", "no MESH", ["check"], RUN, ["give MESH, or --scene"])
case("check", "a selection of the wrong size", check("--sel", "{W}/tube.sel"), RUN, ["tube.sel", "expected 48 entries"],
     {"tube.sel": SEL + "1\n"})
case("check", "a mesh without faces", check(mesh="{W}/m.off"), RUN, ["m.off"], {"m.off": "OFF\n3 0 0\n0 0 0\n1 0 0\n0 1 0\n"})
case("check", "a NaN coordinate", check(mesh="{W}/m.off"), RUN, ["m.off", "nan"],
     {"m.off": OFF.replace("\n1 0 0\n", "\nnan 0 0\n", 1)})
case("check", "an empty file", check(mesh="{W}/m.off"), RUN, ["m.off", "empty file"], {"m.off": ""})

# Matrix Market inputs of `qpr qp`.
case("matrix", "2^31 x 2^31 header (was std::bad_alloc)", qp(H="{W}/h.mtx"), RUN,
     ["h.mtx:2", "2147483648 rows", "more than a file of"],
     {"h.mtx": "%%MatrixMarket matrix coordinate real symmetric\n2147483648 2147483648 1\n1 1 1\n"}, max_seconds=5)
case("matrix", "2^28 rows (was 3 GB and 9 s)", qp(H="{W}/h.mtx"), RUN, ["h.mtx:2", "268435456 rows"],
     {"h.mtx": "%%MatrixMarket matrix coordinate real symmetric\n268435456 268435456 1\n1 1 1\n"}, max_seconds=5)
case("matrix", "more entries than the file holds", qp(H="{W}/h.mtx"), RUN, ["h.mtx:2", "cannot fit"],
     {"h.mtx": "%%MatrixMarket matrix coordinate real symmetric\n4 4 1000000000\n1 1 1\n"}, max_seconds=5)
case("matrix", "dense array larger than the file", qp(H="{W}/h.mtx"), RUN, ["h.mtx:2", "cannot fit"],
     {"h.mtx": "%%MatrixMarket matrix array real general\n100000 100000\n1\n"}, max_seconds=5)
case("matrix", "NaN value", qp(H="{W}/h.mtx"), RUN, ["h.mtx:3", "not finite"], {"h.mtx": H.replace("1 1 1", "1 1 nan")})
case("matrix", "duplicate entry", qp(H="{W}/h.mtx"), RUN, ["h.mtx", "duplicate entry (2, 2)"],
     {"h.mtx": H.replace("4 4 4", "4 4 5") + "2 2 1\n"})
case("matrix", "not symmetric", qp(H="{W}/h.mtx"), RUN, ["h.mtx", "not symmetric"],
     {"h.mtx": H.replace("symmetric", "general").replace("4 4 4", "4 4 5") + "1 2 1\n"})
case("matrix", "wrong header", qp(H="{W}/h.mtx"), RUN, ["h.mtx:1", "%%MatrixMarket"], {"h.mtx": "hello\n"})
case("matrix", "row out of range", qp(H="{W}/h.mtx"), RUN, ["h.mtx", "row 9 out of range"],
     {"h.mtx": H.replace("4 4 1", "9 4 1")})
case("matrix", "b of the wrong size", qp(), RUN, ["b_d0.mtx", "expected 1 rows, got 2"],
     {"dem/b_d0.mtx": "%%MatrixMarket matrix array real general\n2 1\n1\n1\n"})
case("matrix", "manifest: duplicate demand names", qp(demands="{W}/m.json"), RUN,
     ["m.json", "duplicate", "'d'"],
     {"m.json": '{"demands": [{"name": "d", "A": "dem/A_d0.mtx", "b": "dem/b_d0.mtx"},'
                ' {"name": "d", "A": "dem/A_d0.mtx", "b": "dem/b_d0.mtx"}]}'})
case("matrix", "manifest: duplicate JSON key", qp(demands="{W}/m.json"), RUN, ["m.json", "/demands/0: duplicate key 'b'"],
     {"m.json": '{"demands": [{"name": "d", "A": "dem/A_d0.mtx", "b": "dem/b_d0.mtx", "b": "x.mtx"}]}'})
case("matrix", "manifest: missing b", qp(demands="{W}/m.json"), RUN, ["m.json", "missing \"b\""],
     {"m.json": '{"demands": [{"name": "d", "A": "dem/A_d0.mtx"}]}'})
case("matrix", "manifest: syntax error", qp(demands="{W}/m.json"), RUN, ["m.json", "parse error"],
     {"m.json": '{"demands": [}'})
case("matrix", "manifest: a number too large for a double", qp(demands="{W}/m.json"), RUN,
     ["m.json", "number overflow"], {"m.json": '{"demands": [], "x": 1e400}'})
INCONSISTENT = {"dem/A_d0.mtx": "%%MatrixMarket matrix coordinate real general\n4 2 2\n2 1 1\n2 2 1\n",
                "dem/b_d0.mtx": "%%MatrixMarket matrix array real general\n2 1\n1\n2\n"}
case("matrix", "inconsistent demand is a warning on stderr (was only in the JSON)", qp(), 0,
     ["warning", "demand 'd0'", "constraints-least-squares"], INCONSISTENT)
case("matrix", "inconsistent demand with --strict fails", qp("--strict"), 3,
     ["error", "demand 'd0'", "constraints-least-squares"], INCONSISTENT)
case("matrix", "demand directory without demands", qp(demands="{W}/empty"), RUN, ["empty", "no demands"],
     {"empty/readme.txt": "x"})

# ---------------------------------------------------------------- writers
# Each writer against /dev/full, a missing directory and a file-size limit:
# non-zero exit, the message, the earlier file intact, no temporary left.

WRITERS = [
    # (name, args with {OUT}, extension, message words of the failure)
    ("deform --out .off", deform("--out", "{OUT}"), ".off"),
    ("deform --out .obj", deform("--out", "{OUT}"), ".obj"),
    ("deform --out .ply", deform("--out", "{OUT}"), ".ply"),
    ("deform --report", deform("--report", "{OUT}"), ".json"),
    ("deform --cache", deform("--cache", "{OUT}"), ".qpr"),
    ("qp --report", qp("--report", "{OUT}"), ".json"),
    ("theorem --json", ["theorem", "--trials", "10", "--json", "{OUT}"], ".json"),
    ("theorem --csv", ["theorem", "--trials", "10", "--csv", "{OUT}"], ".csv"),
    ("demo --report", ["demo", "--frames", "1", "--out", "{W}/demo", "--report", "{OUT}"], ".json"),
    ("check --report", ["check", "{W}/tube.off", "--report", "{OUT}"], ".json"),
    ("compare --report", ["compare", "{W}/tube.off", "--sel", "{W}/tube.sel", "--def", "{W}/tube.def"] + SMALL[:4] +
     ["--reference", "local-global", "--out-dir", "{W}/cmp", "--report", "{OUT}"], ".json"),
]
EARLIER = "earlier contents\n"
# An earlier cache: a deformer cache's magic bytes, then anything (--cache
# replaces only a file that starts like a cache).
EARLIER_CACHE = "QPREDUCEDEFORMER" + EARLIER
for name, args, ext in WRITERS:
    # Mesh writers pick the format by extension: /dev/full through a link "full.off".
    CASES.append(dict(group="writers", name=name + " to /dev/full",
                      args=[a.replace("{OUT}", "{W}/full" + ext) for a in args],
                      code=3 if name.startswith("theorem") else RUN, words=["full" + ext, "No space left on device"],
                      files={}, max_seconds=None, stdout_words=[], links={"full" + ext: "/dev/full"}))
    case("writers", name + " into a missing directory",
         [a.replace("{OUT}", "{W}/missing/out" + ext) for a in args], 3 if name.startswith("theorem") else RUN,
         ["missing/out" + ext, "does not exist"])
    CASES.append(dict(group="writers", name=name + " under a file-size limit", args=[a.replace("{OUT}", "{W}/out" + ext)
                                                                                    for a in args],
                      code=3 if name.startswith("theorem") else RUN,
                      # demo and compare write meshes first: the limit stops the run there.
                      words=["File too large"] + ([] if name.startswith(("demo", "compare")) else ["out" + ext]),
                      files={"out" + ext: (EARLIER_CACHE if ext == ".qpr" else EARLIER) + "x" * 4096},
                      max_seconds=None, stdout_words=[], fsize=16, intact="out" + ext))
# qp --out X_<name>.mtx: a file-size limit keeps the earlier solution.
CASES.append(dict(group="writers", name="qp --out under a file-size limit", args=qp("--out", "{W}/sol"),
                  code=RUN, words=["X_d0.mtx", "File too large"], files={"sol/X_d0.mtx": EARLIER + "x" * 4096},
                  max_seconds=None, stdout_words=[], fsize=16, intact="sol/X_d0.mtx"))
# A run whose --report directory is missing must not rewrite --out first.
CASES.append(dict(group="writers", name="deform: missing --report directory leaves --out untouched",
                  args=deform("--out", "{W}/keep.off", "--report", "{W}/missing/r.json"), code=RUN,
                  words=["missing/r.json", "does not exist"], files={"keep.off": EARLIER}, max_seconds=None,
                  stdout_words=[], intact="keep.off"))

# Multi-file outputs (docs/robustness.md, "Outputs written as several files"):
# every file atomic, every destination checked before the run; a failure
# midway leaves the files written before it complete and new, the rest as
# they were, and no temporary.


def box_tets(nx=2, ny=2, nz=4):
    """A box of nx × ny × nz cubes, six positive tets each, as MEDIT text, and a
    .sel fixing the bottom layer and moving the top one."""
    V = [(i, j, k) for k in range(nz + 1) for j in range(ny + 1) for i in range(nx + 1)]
    vid = lambda i, j, k: i + (nx + 1) * (j + (ny + 1) * k)
    T = []
    for i in range(nx):
        for j in range(ny):
            for k in range(nz):
                c = [vid(i + (b & 1), j + (b >> 1 & 1), k + (b >> 2 & 1)) for b in range(8)]
                for a, b in ((1, 3), (1, 5), (2, 3), (2, 6), (4, 5), (4, 6)):  # Freudenthal: 0 → a → a|b → 7
                    t = [c[0], c[a], c[a | b], c[7]]
                    p = [V[x] for x in t]
                    d = [[p[r][q] - p[0][q] for q in range(3)] for r in (1, 2, 3)]
                    det = (d[0][0] * (d[1][1] * d[2][2] - d[1][2] * d[2][1]) - d[0][1] * (d[1][0] * d[2][2] - d[1][2] * d[2][0])
                           + d[0][2] * (d[1][0] * d[2][1] - d[1][1] * d[2][0]))
                    T.append(t if det > 0 else [t[0], t[2], t[1], t[3]])
    mesh = "MeshVersionFormatted 1\nDimension 3\nVertices\n%d\n" % len(V)
    mesh += "".join("%d %d %d 0\n" % v for v in V)
    mesh += "Tetrahedra\n%d\n" % len(T) + "".join("%d %d %d %d 0\n" % tuple(x + 1 for x in t) for t in T) + "End\n"
    sel = "".join("%d\n" % (0 if v[2] == 0 else 2 if v[2] == nz else 1) for v in V)
    return mesh, sel


BOX_MESH, BOX_SEL = box_tets()
TETS = {"box.mesh": BOX_MESH, "box.sel": BOX_SEL}
for ext in (".mesh", ".node"):
    name = "deform --out %s (tets)" % ext
    args = ["deform", "{W}/box.mesh", "--sel", "{W}/box.sel", "--def", "{W}/tube.def"] + SMALL + ["--out"]
    CASES.append(dict(group="writers", name=name + " to /dev/full", args=args + ["{W}/full" + ext], code=RUN,
                      words=["full" + ext, "No space left on device"], files=dict(TETS), max_seconds=None,
                      stdout_words=[], links={"full" + ext: "/dev/full"}))
    CASES.append(dict(group="writers", name=name + " into a missing directory",
                      args=args + ["{W}/missing/out" + ext], code=RUN, words=["missing/out" + ext, "does not exist"],
                      files=dict(TETS), max_seconds=None, stdout_words=[]))
    CASES.append(dict(group="writers", name=name + " under a file-size limit", args=args + ["{W}/out" + ext],
                      code=RUN, words=["File too large"], files=dict(TETS, **{"out" + ext: EARLIER + "x" * 4096}),
                      max_seconds=None, stdout_words=[], fsize=16, intact="out" + ext))
# TetGen writes .node, .ele and .face together: the .ele failing keeps the earlier .node.
CASES.append(dict(group="writers", name="deform --out .node (tets): the .ele on /dev/full keeps the earlier .node",
                  args=["deform", "{W}/box.mesh", "--sel", "{W}/box.sel", "--def", "{W}/tube.def"] + SMALL +
                  ["--out", "{W}/out.node"], code=RUN, words=["out.ele", "No space left on device"],
                  files=dict(TETS, **{"out.node": EARLIER}), max_seconds=None, stdout_words=[],
                  links={"out.ele": "/dev/full"}, intact="out.node"))
# Every frame to its own file: frame 1 fails on a full device after frame 0
# was written; the earlier file of frame 2 (never reached) is intact.
FRAMES3 = SMALL[:4] + ["--frames", "3"]
CASES.append(dict(group="writers", name="deform --out {frame}: a failure at frame 1 keeps the later earlier files",
                  args=deform("--out", "{W}/f_{frame}.off", small=FRAMES3), code=RUN,
                  words=["f_001.off", "No space left on device"], files={"f_002.off": EARLIER}, max_seconds=None,
                  stdout_words=[], links={"f_001.off": "/dev/full"}, intact="f_002.off"))
CASES.append(dict(group="writers", name="deform --out {frame} into a missing directory",
                  args=deform("--out", "{W}/missing/f_{frame}.off", small=FRAMES3), code=RUN,
                  words=["missing/f_", "does not exist"], files={}, max_seconds=None, stdout_words=[]))
# qp --out X_<name>.mtx, one file per demand.
CASES.append(dict(group="writers", name="qp --out to /dev/full", args=qp("--out", "{W}/sol"), code=RUN,
                  words=["X_d0.mtx", "No space left on device"], files={"sol/keep.txt": EARLIER}, max_seconds=None,
                  stdout_words=[], links={"sol/X_d0.mtx": "/dev/full"}, intact="sol/keep.txt"))
# (qp creates a missing --out folder; one under a regular file cannot be made.)
CASES.append(dict(group="writers", name="qp --out under a regular file", args=qp("--out", "{W}/tube.off/sol"),
                  code=RUN, words=["tube.off/sol"], files={}, max_seconds=None, stdout_words=[]))
# The meshes of demo and compare (their folders are created; a limit stops the first mesh).
CASES.append(dict(group="writers", name="demo --out meshes under a file-size limit",
                  args=["demo", "--frames", "1", "--out", "{W}/demo"], code=RUN, words=["cylinder_rest.off", "File too large"],
                  files={"demo/cylinder_rest.off": EARLIER + "x" * 4096}, max_seconds=None, stdout_words=[], fsize=16,
                  intact="demo/cylinder_rest.off"))
CASES.append(dict(group="writers", name="compare --out-dir meshes under a file-size limit",
                  args=["compare", "{W}/tube.off", "--sel", "{W}/tube.sel", "--def", "{W}/tube.def"] + SMALL[:4] +
                  ["--reference", "local-global", "--out-dir", "{W}/cmp"], code=RUN, words=["reduced.off", "File too large"],
                  files={"cmp/reduced.off": EARLIER + "x" * 4096}, max_seconds=None, stdout_words=[], fsize=16,
                  intact="cmp/reduced.off"))

# A failing run writes nothing (docs/robustness.md, "What a failing run
# writes"): its outputs are staged and put in place only when it succeeds,
# so a failure after some of them were written leaves every earlier file as
# it was, and the folders it made for them are removed.
CASES.append(dict(group="writers", name="qp --check-full: a failed full solve (exit 3) keeps the earlier X and report",
                  args=qp("--check-full", "--out", "{W}/sol", "--report", "{W}/r.json"), code=3,
                  words=["demand 'd0'", "full solve failed"],
                  files=dict(INCONSISTENT, **{"sol/X_d0.mtx": EARLIER, "r.json": EARLIER}), max_seconds=None,
                  stdout_words=[], intact=["sol/X_d0.mtx", "r.json"]))
CASES.append(dict(group="writers", name="deform: a failure after the precompute keeps the earlier --cache",
                  args=deform("--cache", "{W}/c.qpr", "--report", "{W}/r.json", "--out", "{W}/pose.xyz"), code=RUN,
                  words=["pose.xyz", "unsupported"], files={"c.qpr": EARLIER_CACHE, "r.json": EARLIER}, max_seconds=None,
                  stdout_words=[], intact=["c.qpr", "r.json"]))
CASES.append(dict(group="writers", name="demo: a failing run removes the --out folder it made",
                  args=["demo", "--frames", "1", "--out", "{W}/new/demo", "--report", "{W}/missing/r.json"],
                  code=RUN, words=["missing/r.json", "does not exist"], files={}, max_seconds=None, stdout_words=[],
                  absent=["new"]))
CASES.append(dict(group="writers", name="theorem: --csv failing keeps the earlier --json",
                  args=["theorem", "--trials", "10", "--json", "{W}/t.json", "--csv", "{W}/full.csv"], code=3,
                  words=["full.csv", "No space left on device"], files={"t.json": EARLIER}, max_seconds=None,
                  stdout_words=[], links={"full.csv": "/dev/full"}, intact=["t.json"]))

# No output may be an input (docs/robustness.md): a path given twice, through
# a symbolic or a hard link, or a --cache that is not a cache, is refused
# before any work, naming both options; the inputs stay as they were.
SAME = "name the same file"
for name, args, words, links, hardlinks, intact in [
    ("deform --cache MESH", deform("--cache", "{W}/tube.off"), ["MESH and --cache " + SAME, "cache would replace"],
     {}, {}, ["tube.off"]),
    ("deform --cache SEL", deform("--cache", "{W}/tube.sel"), ["--sel and --cache " + SAME], {}, {}, ["tube.sel"]),
    ("deform --out and --report the same", deform("--out", "{W}/x.off", "--report", "{W}/x.off"),
     ["--out and --report " + SAME, "one output would overwrite the other", "another path for --report"], {}, {}, []),
    ("deform --out through a symbolic link to MESH", deform("--out", "{W}/link.off"),
     ["MESH and --out " + SAME, "link.off and", "tube.off are one file"], {"link.off": "tube.off"}, {}, ["tube.off"]),
    ("deform --report a hard link of --def", deform("--report", "{W}/hard.def"), ["--def and --report " + SAME],
     {}, {"hard.def": "tube.def"}, ["tube.def"]),
    ("deform --out MESH spelled another way", deform("--out", "{W}/./dem/../tube.off"), ["MESH and --out " + SAME],
     {}, {}, ["tube.off"]),
    ("deform --cache a file that is not a cache", deform("--cache", "{W}/tube.obj"),
     ["--cache", "tube.obj exists and is not a qpreduce cache"], {}, {}, ["tube.obj"]),
    ("check --report MESH", check("--report", "{W}/tube.off"), ["MESH and --report " + SAME], {}, {}, ["tube.off"]),
    ("qp --report H", qp("--report", "{W}/H.mtx"), ["--H and --report " + SAME], {}, {}, ["H.mtx"]),
    ("theorem --json and --csv the same", ["theorem", "--trials", "10", "--json", "{W}/t", "--csv", "{W}/t"],
     ["--json and --csv " + SAME], {}, {}, []),
]:
    CASES.append(dict(group="writers", name=name, args=args, code=RUN, words=words, files={}, max_seconds=10,
                      stdout_words=[], links=links, hardlinks=hardlinks, intact=intact))
# The files a scene names and the rest of a TetGen set are inputs too.
TETGEN_NODE = "5 3 0 0\n1 0 0 0\n2 1 0 0\n3 0 1 0\n4 0 0 1\n5 0 0 -1\n"
TETGEN_ELE = "2 4 0\n1 1 2 3 4\n2 1 3 2 5\n"
DEF_SCENE = scene(', "handles": [{"vertices": [3], "def": "tube.def"}]')
for name, args, words, files, intact in [
    ("deform --out the mesh --scene names", ["deform", "--scene", "{W}/s.json", "--out", "{W}/tube.off"],
     ["--scene's /mesh and --out " + SAME, "another path for --out"], {"s.json": DEF_SCENE}, ["tube.off", "s.json"]),
    ("deform --report the .def --scene names", ["deform", "--scene", "{W}/s.json", "--report", "{W}/tube.def"],
     ["--scene's /handles/0/def and --report " + SAME], {"s.json": DEF_SCENE}, ["tube.def"]),
    ("check --report the mesh --scene names", ["check", "--scene", "{W}/s.json", "--report", "{W}/tube.off"],
     ["--scene's /mesh and --report " + SAME], {"s.json": DEF_SCENE}, ["tube.off"]),
    ("check --report the .ele of a TetGen MESH", check("--report", "{W}/t.ele", mesh="{W}/t.node"),
     ["MESH (its .ele) and --report " + SAME], {"t.node": TETGEN_NODE, "t.ele": TETGEN_ELE}, ["t.ele"]),
]:
    CASES.append(dict(group="writers", name=name, args=args, code=RUN, words=words, files=files, max_seconds=10,
                      stdout_words=[], intact=intact))
# The standard output is a writer too: a command whose tables cannot be
# written fails.
CASES.append(dict(group="writers", name="check with the standard output on /dev/full", args=check(), code=RUN,
                  words=["writing the standard output failed", "No space left on device"], files={},
                  max_seconds=None, stdout_words=[], stdout="/dev/full"))
CASES.append(dict(group="writers", name="check with the standard output closed", args=check(), code=RUN,
                  words=["the standard output is closed"], files={}, max_seconds=None, stdout_words=[],
                  stdout="closed"))

# ---------------------------------------------------------------- memory
# Under an address-space limit (`ulimit -v`): a clear message within seconds
# instead of OpenBLAS retrying its buffer for ever (apps/qpr/blas_memory.h);
# enough for the tube runs. Skipped in the sanitizer build, whose shadow
# memory needs the address space.
MIB_KB = 1024
for name, args, vlimit_mb, code, words in [
    ("deform under ulimit -v 146 MB", deform(), 146, RUN,
     ["out of memory", "address-space limit (ulimit -v) of 146 MB", "raise the limit by"]),
    ("qp under ulimit -v 146 MB", qp(), 146, RUN, ["out of memory", "ulimit -v"]),
    ("deform under ulimit -v 600 MB runs", deform(), 600, 0, []),
    ("check under ulimit -v 146 MB runs (it was left waiting at exit)", check(), 146, CLEAN, []),
]:
    CASES.append(dict(group="memory", name=name, args=args, code=code, words=words, files={}, max_seconds=30,
                      stdout_words=[], vlimit=vlimit_mb * MIB_KB))

# ---------------------------------------------------------------- view
# The viewer's writers, headless (--screenshot renders the last frame, then
# writes the PNG, the --out mesh and the --stats JSON in that order) and in the
# window mode (--max-frames with --window-screenshot), each against /dev/full,
# a missing directory and a file-size limit like the writers above. The
# screenshot goes to /dev/null where another writer is under test: a device
# is written in place and knows no file-size limit, so the limit reaches the
# writer under test. Mesa renders in software; its shader cache stays off so
# that the limit meets no other file.
VIEW_ENV = {"LIBGL_ALWAYS_SOFTWARE": "1", "MESA_SHADER_CACHE_DISABLE": "true"}
VIEW_TUBE = ["view", "{W}/tube.off", "--sel", "{W}/tube.sel", "--def", "{W}/tube.def"] + SMALL + ["--size", "32x32"]
VIEW_BOX = ["view", "{W}/box.mesh", "--sel", "{W}/box.sel", "--def", "{W}/tube.def"] + SMALL + ["--size", "32x32"]
VIEW_WRITERS = [
    # (name, args with {OUT}, extension, extra input files)
    ("view --screenshot", VIEW_TUBE + ["--screenshot", "{OUT}"], ".png", {}),
    ("view --stats", VIEW_TUBE + ["--screenshot", "/dev/null", "--stats", "{OUT}"], ".json", {}),
    ("view --out .off", VIEW_TUBE + ["--screenshot", "/dev/null", "--out", "{OUT}"], ".off", {}),
    ("view --out .mesh (tets)", VIEW_BOX + ["--screenshot", "/dev/null", "--out", "{OUT}"], ".mesh", TETS),
    ("view --window-screenshot", VIEW_TUBE + ["--max-frames", "3", "--window-screenshot", "{OUT}"], ".png", {}),
]
for name, args, ext, inputs in VIEW_WRITERS:
    view = dict(group="view", code=RUN, max_seconds=None, stdout_words=[], env=VIEW_ENV, display=True)
    CASES.append(dict(view, name=name + " to /dev/full", args=[a.replace("{OUT}", "{W}/full" + ext) for a in args],
                      words=["full" + ext, "No space left on device"], files=dict(inputs),
                      links={"full" + ext: "/dev/full"}))
    CASES.append(dict(view, name=name + " into a missing directory",
                      args=[a.replace("{OUT}", "{W}/missing/out" + ext) for a in args],
                      words=["missing/out" + ext, "does not exist"], files=dict(inputs)))
    CASES.append(dict(view, name=name + " under a file-size limit",
                      args=[a.replace("{OUT}", "{W}/out" + ext) for a in args], words=["out" + ext, "File too large"],
                      files=dict(inputs, **{"out" + ext: EARLIER + "x" * 4096}), fsize=16, intact="out" + ext))
# The mesh failing stops the run: the earlier --stats file (written last) stays.
CASES.append(dict(group="view", name="view: --out on /dev/full keeps the earlier --stats file",
                  args=VIEW_TUBE + ["--screenshot", "{W}/shot.png", "--out", "{W}/full.off", "--stats", "{W}/s.json"],
                  code=RUN, words=["full.off", "No space left on device"], files={"s.json": EARLIER},
                  max_seconds=None, stdout_words=[], env=VIEW_ENV, display=True, links={"full.off": "/dev/full"},
                  intact="s.json"))

CASES.append(dict(group="view", name="view --screenshot and --stats the same file",
                  args=VIEW_TUBE + ["--screenshot", "{W}/v.png", "--stats", "{W}/v.png"], code=RUN,
                  words=["--screenshot and --stats name the same file"], files={}, max_seconds=10,
                  stdout_words=[], env=VIEW_ENV, display=True))

# ---------------------------------------------------------------- runner


def temporaries(root):
    found = []
    for d, _, names in os.walk(root):
        found += [os.path.join(d, n) for n in names
                  if re.match(r"^\..*\.tmp\.\d+\.\d+$", n) or n.endswith(".tmp") or n.startswith(".qpr-run.")]
    return found


def run_case(qpr, c):
    work = tempfile.mkdtemp(prefix="qpr_bad_input_")
    try:
        files = base_files()
        files.update(c["files"])
        for rel, text in files.items():
            path = os.path.join(work, rel)
            os.makedirs(os.path.dirname(path), exist_ok=True)
            with open(path, "w", encoding="utf-8", newline="") as f:
                f.write(text)
        for rel, target in c.get("links", {}).items():
            os.symlink(target, os.path.join(work, rel))
        for rel, target in c.get("hardlinks", {}).items():
            os.link(os.path.join(work, target), os.path.join(work, rel))
        args = [qpr] + [a.replace("{W}", work) for a in c["args"]]
        fsize = c.get("fsize")

        vlimit = c.get("vlimit")

        def limit():
            if vlimit:
                resource.setrlimit(resource.RLIMIT_AS, (vlimit * 1024, resource.getrlimit(resource.RLIMIT_AS)[1]))
            if fsize:
                signal.signal(signal.SIGXFSZ, signal.SIG_DFL)  # qpr itself must ignore it
                resource.setrlimit(resource.RLIMIT_FSIZE, (fsize, resource.getrlimit(resource.RLIMIT_FSIZE)[1]))

        start = time.monotonic()
        # "stdout": a file to write the standard output to (/dev/full), or
        # "closed" (closed in the child before qpr starts).
        sink_path = c.get("stdout")

        def prepare():
            limit()
            if sink_path == "closed":
                os.close(1)

        sink = open(sink_path, "wb") if sink_path not in (None, "closed") else None
        try:
            p = subprocess.run(args, cwd=work, stdout=sink or subprocess.PIPE, stderr=subprocess.PIPE,
                               preexec_fn=prepare, timeout=300, env=dict(os.environ, **c.get("env", {})))
        finally:
            if sink:
                sink.close()
        p.stdout = p.stdout or b""
        seconds = time.monotonic() - start
        err = p.stderr.decode("utf-8", "replace")
        out = p.stdout.decode("utf-8", "replace")
        problems = []
        if p.returncode != c["code"]:
            problems.append("exit code %d, expected %d" % (p.returncode, c["code"]))
        for w in c["words"]:
            if w.replace("{W}", work) not in err:
                problems.append("stderr lacks %r" % w)
        for w in c["stdout_words"]:
            if w not in out:
                problems.append("stdout lacks %r" % w)
        for w in c.get("stderr_absent", []):
            if w in err:
                problems.append("stderr has %r" % w)
        if c["code"] != 0 and len(err) > 2000:
            problems.append("stderr is %d characters long" % len(err))
        if c["max_seconds"] and seconds > c["max_seconds"]:
            problems.append("took %.1f s (at most %g)" % (seconds, c["max_seconds"]))
        intact = c.get("intact") or []
        for rel in [intact] if isinstance(intact, str) else intact:
            with open(os.path.join(work, rel), "rb") as f:  # a failed case may leave any bytes
                if f.read() != files[rel].encode("utf-8"):
                    problems.append("the earlier %s was changed" % rel)
        for rel in c.get("absent", []):
            if os.path.exists(os.path.join(work, rel)):
                problems.append("%s was left behind" % rel)
        left = temporaries(work)
        if left:
            problems.append("temporary files left: %s" % ", ".join(os.path.relpath(t, work) for t in left))
        return problems, " ".join(args)[:300], p.returncode, err[-1500:]
    finally:
        shutil.rmtree(work, ignore_errors=True)


# Writers whose whole output is under 1 KiB (main: LLVM's libomp).
FITS_IN_1KIB = {"qp --report under a file-size limit", "check --report under a file-size limit",
                "qp --out under a file-size limit", "view --screenshot under a file-size limit",
                "view --stats under a file-size limit", "view --window-screenshot under a file-size limit"}


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("qpr")
    ap.add_argument("--group", action="append")
    ap.add_argument("--list", action="store_true")
    a = ap.parse_args()
    cases = [c for c in CASES if not a.group or c["group"] in a.group]
    if a.list:
        for c in cases:
            print("%-8s %s" % (c["group"], c["name"]))
        print("%d cases" % len(cases))
        return 0
    if any(c.get("display") for c in cases):
        if subprocess.run([a.qpr, "view", "--help"], stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL).returncode:
            print("skipped [view]: %s has no `view` command (built with QPREDUCE_BUILD_VIEWER=OFF)" % a.qpr)
            cases = [c for c in cases if not c.get("display")]
        elif not os.environ.get("DISPLAY"):
            xvfb = shutil.which("xvfb-run")
            if not xvfb:
                print("FAIL: the view cases need a display and xvfb-run is not installed (scripts/install-deps.sh)")
                return 1
            # Again under a virtual X server (before anything is printed, so
            # that the skips below are said once); only qpr gets the cases'
            # file-size limits, not the server.
            return subprocess.run([xvfb, "-a", sys.executable] + sys.argv).returncode
    if os.environ.get("QPREDUCE_SANITIZER_BUILD") and any(c.get("vlimit") for c in cases):
        print("skipped [memory]: an address-space limit leaves AddressSanitizer no room for its shadow memory")
        cases = [c for c in cases if not c.get("vlimit")]
    # LLVM's OpenMP runtime (a clang build: the sanitizer build) registers
    # itself in a 1 KiB shared-memory file at the first parallel region and
    # aborts when a file-size limit forbids it: there the limit is 1 KiB, and
    # the writers whose output fits in 1 KiB are left to a libgomp build
    # (the Release suite runs them all at 16 bytes).
    ldd = shutil.which("ldd")
    if ldd and "libomp" in subprocess.run([ldd, a.qpr], capture_output=True, text=True).stdout:
        small = [c for c in cases if c.get("fsize") and c["name"] in FITS_IN_1KIB]
        for c in small:
            print("skipped [%s] %s: its output fits under the 1 KiB file-size limit that LLVM's libomp needs "
                  "(run by a libgomp build)" % (c["group"], c["name"]))
        cases = [dict(c, fsize=max(c["fsize"], 1024)) if c.get("fsize") else c for c in cases if c not in small]
    failed = 0
    for c in cases:
        problems, cmd, code, err = run_case(a.qpr, c)
        if problems:
            failed += 1
            print("FAIL [%s] %s: %s\n  $ %s\n  exit %d, stderr:\n    %s" %
                  (c["group"], c["name"], "; ".join(problems), cmd, code, err.strip().replace("\n", "\n    ")))
        else:
            print("ok   [%s] %s" % (c["group"], c["name"]))
    print("%d of %d cases passed" % (len(cases) - failed, len(cases)))
    return 1 if failed else 0


if __name__ == "__main__":
    sys.exit(main())
