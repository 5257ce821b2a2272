#!/usr/bin/env bash
# The office results of docs/results/office.md: the evidence protocol (2000 test images per set, both
# test sets, k = 10 and 20, 4 random and 4 uniform runs; OMP with the paper's and the corners
# marker model, human, expected-recall) with the oracle ceiling and the score's calibration on
# map images. About 3.5 hours on 2 cores (each placement re-renders nearly every image: about
# 4 min per placement); every stage is cached in out/ and an interrupted run resumes.
# The protocol was first k = 5, 10, 15, 20 with 5 runs (about 6 hours); it was cut to this one to
# fit the session's CPU budget before any recall table had been computed.
set -euo pipefail
cd "$(dirname "$0")/.."
MP=.venv/bin/markerplace
$MP --quiet plan office -k 20 --marker-model corners --out out/office_corners
mkdir -p out/placements_office/omp-corners
cp out/office_corners/placement.json out/placements_office/omp-corners/
time $MP --quiet evaluate office --out out/eval_office --tests 2000 --k 10,20 --runs 4 \
  --placements out/placements_office --ceiling --calibration
