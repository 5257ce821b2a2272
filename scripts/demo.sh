#!/usr/bin/env bash
# The README's demo (run by `make demo` after set-up): look at the built-in scenes, plan markers
# with OMP on a floor built for planning to pay (`corridor-small`: four identical guest rooms off a
# plain corridor), plan on a scan-like mesh, and measure on a short simulation whether the plan
# beats random and evenly spaced tags (its protocol: docs/protocols.md, "Demo: corridor-small").
# Measured on a fresh clone, set-up included: 6 min 55 s wall, 648 CPU-seconds on 2 idle cores (docs/results/corridor.md, the demo).
# Ends by printing the path of the plan's report.html.
set -euo pipefail
cd "$(dirname "$0")/.."
MP=${DEMO_MP:-.venv/bin/markerplace}
OUT=${DEMO_OUT:-out/demo}
SCENE=${DEMO_SCENE:-corridor-small}
GRID=${DEMO_GRID:-1.0}  # camera grid spacing, metres (the default 0.5 quadruples the demo's time)
mkdir -p "$OUT"

echo "== built-in scenes"
$MP scene list

echo "== three views of the office"
$MP render office --pose 4.5,3.0,1.5,90 --out "$OUT/office_view1" >/dev/null
$MP render office --pose 11.0,2.5,1.5,0 --out "$OUT/office_view2" >/dev/null
$MP render office --out "$OUT/office_view3" >/dev/null
echo "wrote $OUT/office_view{1,2,3}_rgb.png (and _depth.npy, _normal.png)"

echo "== OMP plan: 4 markers in '$SCENE' (camera grid $GRID m; the marker-free map for the evaluation made on the way)"
$MP plan "$SCENE" -k 4 --grid-spacing "$GRID" --with-map --out "$OUT/plan_$SCENE"
$MP render "$SCENE" --markers "$OUT/plan_$SCENE/placement.json" --out "$OUT/${SCENE}_with_markers" >/dev/null
echo "see $OUT/plan_$SCENE/report.html (open it in a browser: maps, and each tag with the view an installer has), placement.csv"

echo "== a scan-like mesh: a simulated RGB-D walk through 'tiny', fused, then planned on"
$MP --quiet scene export tiny "$OUT/tiny_scan.ply" --as-scan
$MP plan "$OUT/tiny_scan.ply" -k 4 --out "$OUT/plan_tiny_scan"
echo "see $OUT/plan_tiny_scan/placement.png (planned on the fused scan, not the procedural model)"

if [ "${DEMO_SKIP_EVAL:-0}" != "1" ]; then
  echo "== short evaluation of the plan: OMP vs no markers vs 3 random and 3 uniform placements (paired 95 % intervals)"
  $MP evaluate --plan "$OUT/plan_$SCENE" --out "$OUT/eval_$SCENE" --tests 400 --test-sets weighted --runs 3 --k 2,4 \
    --methods none,omp,random,uniform
  echo "see $OUT/eval_$SCENE/report.html (recall tables, recall vs k, test images the plan fixes and breaks), tables.md"
fi
echo "demo outputs are in $OUT; the plan of '$SCENE', for the people who hang the tags:"
realpath "$OUT/plan_$SCENE/report.html"
