#!/usr/bin/env bash
# Prepare the real RGB-D sequence of the real-photograph experiment (docs/protocols.md,
# "Kitchen, real frames"): the 1000 frames of the 7-Scenes "redkitchen" scene that the public
# repository andyzeng/tsdf-fusion-python ships in its folder data/.
#
# The frames are under Microsoft's non-commercial research licence (7-Scenes): they are never
# committed here. Give the path of a checkout of that repository (or of its data/ folder); the
# frames are linked, not copied, into runs/kitchen/frames (runs/ is ignored by git).
#
#   scripts/prepare_kitchen.sh /path/to/tsdf-fusion-python
#   .venv/bin/markerplace evaluate --frames runs/kitchen/frames --out runs/kitchen/eval ...
set -euo pipefail
cd "$(dirname "$0")/.."
src=${1:?usage: scripts/prepare_kitchen.sh PATH (a checkout of tsdf-fusion-python, or its data/ folder)}
[ -d "$src/data" ] && src="$src/data"
if [ ! -f "$src/frame-000000.pose.txt" ] || [ ! -f "$src/camera-intrinsics.txt" ]; then
  echo "prepare_kitchen: $src holds no 7-Scenes frames (frame-000000.pose.txt, camera-intrinsics.txt)" >&2
  exit 2
fi
n=$(ls "$src" | grep -c '^frame-[0-9]*\.pose\.txt$')
if [ "$n" -ne 1000 ]; then
  echo "prepare_kitchen: expected the 1000 frames of the kitchen sequence, found $n in $src" >&2
  exit 2
fi
mkdir -p runs/kitchen
rm -f runs/kitchen/frames
ln -s "$(cd "$src" && pwd)" runs/kitchen/frames
echo "prepare_kitchen: runs/kitchen/frames -> $(cd "$src" && pwd) ($n frames, 7-Scenes layout)"
