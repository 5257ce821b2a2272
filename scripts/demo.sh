#!/usr/bin/env bash
# The README's demo (run by `make demo` after set-up): look at a built-in scene, plan markers
# with OMP, plan on a scan-like mesh, and prove on a short simulation that the markers help.
# About 12 minutes on 2 cores (18 min measured with other jobs on the cores). Ends by printing the path of the plan's report.html.
set -euo pipefail
cd "$(dirname "$0")/.."
MP=.venv/bin/markerplace
OUT=${DEMO_OUT:-out/demo}
SCENE=${DEMO_SCENE:-room}
mkdir -p "$OUT"

echo "== built-in scenes"
$MP scene list

echo "== three views of the office"
$MP render office --pose 4.5,3.0,1.5,90 --out "$OUT/office_view1" >/dev/null
$MP render office --pose 11.0,2.5,1.5,0 --out "$OUT/office_view2" >/dev/null
$MP render office --out "$OUT/office_view3" >/dev/null
echo "wrote $OUT/office_view{1,2,3}_rgb.png (and _depth.npy, _normal.png)"

echo "== OMP plan: 6 markers in '$SCENE' (it has 11 spots a person would use)"
$MP plan "$SCENE" -k 6 --out "$OUT/plan_$SCENE"
$MP render "$SCENE" --markers "$OUT/plan_$SCENE/placement.json" --out "$OUT/${SCENE}_with_markers" >/dev/null
echo "see $OUT/plan_$SCENE/report.html (open it in a browser: maps, and each tag with the view an installer has), placement.csv"

echo "== a scan-like mesh: a simulated RGB-D walk through 'tiny', fused, then planned on"
$MP --quiet scene export tiny "$OUT/tiny_scan.ply" --as-scan
$MP plan "$OUT/tiny_scan.ply" -k 4 --out "$OUT/plan_tiny_scan"
echo "see $OUT/plan_tiny_scan/placement.png (planned on the fused scan, not the procedural model)"

if [ "${DEMO_SKIP_EVAL:-0}" != "1" ]; then
  echo "== short evaluation: OMP vs no markers vs 3 random and 3 uniform placements (paired 95 % intervals)"
  $MP evaluate "$SCENE" --out "$OUT/eval_$SCENE" --tests 400 --test-sets weighted --runs 3 --k 3,6 \
    --methods none,omp,random,uniform
  echo "see $OUT/eval_$SCENE/report.html (recall tables, recall vs k, test images the plan fixes and breaks), tables.md"
fi
echo "demo outputs are in $OUT; the plan of '$SCENE', for the people who hang the tags:"
realpath "$OUT/plan_$SCENE/report.html"
