#!/usr/bin/env bash
# Regenerates docs/figures/viewer_*.png: headless `qpr view` screenshots of the
# shared models, deformed (docs/viewer.md). Needs xvfb-run (scripts/install-deps.sh)
# and a build with the viewer: QPR=build/bin/qpr by default.
# Usage: scripts/viewer-figures.sh [QPR]   (from the repository root)
set -euo pipefail
QPR=${1:-${QPR:-build/bin/qpr}}
DATA=${DATA:-../shared/data}
BS=$DATA/meshes/botsch-sorkine
OUT=docs/figures
mkdir -p "$OUT"
view() {  # view NAME ARGS…: one 720×450 screenshot
  local name=$1; shift
  LIBGL_ALWAYS_SOFTWARE=1 xvfb-run -a "$QPR" view "$@" --size 720x450 --screenshot "$OUT/viewer_$name.png"
}
view cylinder    $BS/cylinder.off    --sel $BS/cylinder.sel    --def $BS/cylinder.def    --frames 8 --up z --yaw 90
view cactus      $BS/cactus.off      --sel $BS/cactus.sel      --def $BS/cactus.def      --frames 8 --up z --yaw 20
view bar         $BS/bar.off         --sel $BS/bar.sel         --def $BS/bar.def         --frames 8 --up z --yaw 60 --pitch 20
view bumpy_plane $BS/bumpy_plane.off --sel $BS/bumpy_plane.sel --def $BS/bumpy_plane.def --frames 8 --up z --pitch 35 --color deviation
view cactus_anim $BS/cactus.off --anim $DATA/paper-examples/cactus/rotated_hansel.anim --up z --yaw 20 --color linear
view solid_cylinder $DATA/tets/solid_cylinder.node --sel $BS/cylinder.sel --def $BS/cylinder.def --frames 8 --up z --yaw 90
# Dinosaur and dragon: the shared data has no handles for them; these scenes
# pose them with patches (scripts/make_showcase_scenes.py).
SCENES=$(mktemp -d)
python3 scripts/make_showcase_scenes.py "$DATA" "$SCENES"
view dinosaur --scene "$SCENES/dinosaur.json" --up z --color patches
view dragon   --scene "$SCENES/dragon.json" --yaw 25
rm -rf "$SCENES"
