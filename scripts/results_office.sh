#!/usr/bin/env bash
# The office results of docs/results.md: the evidence protocol (2000 test images per set, both
# test sets, k = 5, 10, 15, 20, 5 random and 5 uniform runs; OMP with the paper's and the corners
# marker model, human, expected-recall) with the oracle ceiling and the score's calibration on
# map images. Several hours on 2 cores; every stage is cached in out/ and an interrupted run resumes.
set -euo pipefail
cd "$(dirname "$0")/.."
MP=.venv/bin/markerplace
$MP --quiet plan office -k 20 --marker-model corners --out out/office_corners
mkdir -p out/placements_office/omp-corners
cp out/office_corners/placement.json out/placements_office/omp-corners/
time $MP --quiet evaluate office --out out/eval_office --tests 2000 --k 5,10,15,20 --runs 5 \
  --placements out/placements_office --ceiling --calibration
