#!/usr/bin/env bash
# The other scenes of docs/results/*.md, on one fixed protocol (chosen before any of them ran):
# 500 test images per set, both test sets, k = 5, 10, 20 (the room: 5 and 10, it has 13
# candidate spots), 3 random and 3 uniform runs; OMP with
# the paper's and the corners marker model, human, expected-recall; the oracle ceiling and the
# score's calibration on map images. SCENES picks which (default: room house office_scan studio);
# office_scan is a simulated RGB-D scan of the office (scene export --as-scan, 4 cm voxels).
# K overrides the list of k (its largest is the corners plan's k); EXTRA is appended to every
# evaluate (for example "--tag-ids candidate --test-sets weighted").
set -euo pipefail
cd "$(dirname "$0")/.."
MP=.venv/bin/markerplace
SCENES=${SCENES:-"room house office_scan studio"}
for name in $SCENES; do
  scene=$name
  ks=5,10,20; kmax=20
  if [ "$name" = room ]; then ks=5,10; kmax=10; fi
  if [ -n "${K:-}" ]; then ks=$K; kmax=$(tr ',' '\n' <<<"$K" | sort -n | tail -1); fi
  if [ "$name" = office_scan ]; then
    scene=out/scans/office_scan.ply
    [ -f "$scene" ] || $MP --quiet scene export office "$scene" --as-scan
  fi
  $MP --quiet plan "$scene" -k $kmax --marker-model corners --out "out/${name}_corners"
  mkdir -p "out/placements_$name/omp-corners"
  cp "out/${name}_corners/placement.json" "out/placements_$name/omp-corners/"
  echo "== $name $(date)"
  time $MP --quiet evaluate "$scene" --out "out/eval_$name" --tests 500 --k $ks --runs 3 \
    --placements "out/placements_$name" --ceiling --calibration ${EXTRA:-}
done
