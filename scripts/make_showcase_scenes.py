#!/usr/bin/env python3
"""Writes the JSON scenes of the dinosaur and dragon screenshots (docs/viewer.md)
into OUTDIR, with absolute paths into the shared data. The shared data has
proxies for both but no handles, so the poses are made here:
  * dinosaur: feet Fixed (patches 1, 2 of dinosaur_affine.id), hips a free
    Rigid patch (4), the head an Affine patch (3) turned 35° about x and lifted;
  * dragon: the base (y < 0.058) Fixed, the head (x < −0.04, y > 0.125) an
    Affine patch turned 35° about the up axis and lifted.
Usage: scripts/make_showcase_scenes.py DATA OUTDIR
"""
import json
import math
import os
import sys


def vertices(path):
    with open(path) as f:
        t = [x for line in f for x in line.split("#")[0].split()]
    n = int(t[1])
    return [tuple(float(x) for x in t[4 + 3 * i: 7 + 3 * i]) for i in range(n)]


def turn(c, axis, degrees, lift, frames=4):
    """Per frame: a rotation about `axis` through c, plus a lift, as 4 × 4 rows."""
    out = []
    for f in range(1, frames + 1):
        a = math.radians(degrees) * f / frames
        co, si = math.cos(a), math.sin(a)
        R = {"x": [[1, 0, 0], [0, co, -si], [0, si, co]], "y": [[co, 0, si], [0, 1, 0], [-si, 0, co]]}[axis]
        t = [lift[i] * f / frames for i in range(3)]
        tr = [c[i] - sum(R[i][j] * c[j] for j in range(3)) + t[i] for i in range(3)]
        out.append([R[0] + [tr[0]], R[1] + [tr[1]], R[2] + [tr[2]], [0, 0, 0, 1]])
    return out


def main():
    data, outdir = os.path.abspath(sys.argv[1]), sys.argv[2]
    os.makedirs(outdir, exist_ok=True)
    dino = os.path.join(data, "paper-examples/dinosaur")
    aff = os.path.join(dino, "dinosaur_affine.id")
    V = vertices(os.path.join(dino, "dinosaur.off"))
    ids = [int(x) for x in open(aff).read().split()]
    head = [i for i in range(len(V)) if ids[i] == 3]
    c = [sum(V[i][a] for i in head) / len(head) for a in range(3)]
    scene = {"description": "dinosaur: feet fixed, hips a free rigid patch, head turned and lifted",
             "mesh": os.path.join(dino, "dinosaur.off"),
             "proxies": {"linear": os.path.join(dino, "dinosaur_lin34.id"),
                         "rotational": os.path.join(dino, "dinosaur_cluster30.id")},
             "patches": [{"type": "fixed", "id": {"file": aff, "value": 1}},
                         {"type": "fixed", "id": {"file": aff, "value": 2}},
                         {"type": "affine", "id": {"file": aff, "value": 3}},
                         {"type": "rigid", "id": {"file": aff, "value": 4}}],
             "handles": [{"name": "head", "id": {"file": aff, "value": 3},
                          "transforms": turn(c, "x", 35, [0, -0.004, 0.008])}]}
    with open(os.path.join(outdir, "dinosaur.json"), "w") as f:
        json.dump(scene, f)

    dragon = os.path.join(data, "paper-examples/dragon/dragon.off")
    V = vertices(dragon)
    base = [i for i, v in enumerate(V) if v[1] < 0.058]
    head = [i for i, v in enumerate(V) if v[0] < -0.04 and v[1] > 0.125]
    c = [sum(V[i][a] for i in head) / len(head) for a in range(3)]
    scene = {"description": "dragon: base fixed, head turned about the up axis and lifted",
             "mesh": dragon,
             "proxies": {"rotational": os.path.join(data, "paper-examples/dragon/dragon_cluster30.id")},
             "patches": [{"type": "fixed", "vertices": base}, {"type": "affine", "vertices": head}],
             "handles": [{"name": "head", "vertices": head, "transforms": turn(c, "y", 35, [0, 0.012, 0])}]}
    with open(os.path.join(outdir, "dragon.json"), "w") as f:
        json.dump(scene, f)


if __name__ == "__main__":
    main()
