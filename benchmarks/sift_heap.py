"""What glibc's default heap policy costs SIFT on photographs (markerplace/runtime/heap.py).

Runs the plan's SIFT preset on every ``--step``-th frame of a frame folder twice, each in a fresh
process: with glibc's defaults, and with :func:`markerplace.runtime.heap.keep_freed_memory`.
Per frame: wall, user and system ms and minor page faults (``getrusage``), one OpenCV thread as in
a worker; then the ratios and whether the features are the same (they must be: the allocator's
policy changes no result). Prints ``name: value`` lines.

    .venv/bin/python benchmarks/sift_heap.py [--frames runs/kitchen/frames] [--step 10] [--count 30]
"""

from __future__ import annotations

import argparse
import json
import subprocess
import sys

from scan_plan import emit  # benchmarks/ is on sys.path when run as a script

CHILD = """
import hashlib, json, resource, sys, time
import cv2
import numpy as np
cv2.setNumThreads(1)
from markerplace.runtime.heap import keep_freed_memory
keep = sys.argv[1] == "1" and keep_freed_memory()
from markerplace.localization.sift import extract_sift
from markerplace.plan.config import PlanConfig
from markerplace.scan.frame_images import load_frame
from markerplace.scan.frames import open_frameset
fs = open_frameset(sys.argv[2])
cfg = PlanConfig().imaging.sift
images = [load_frame(fs, fs.frames[i])[0] for i in range(0, len(fs.frames), int(sys.argv[3]))][:int(sys.argv[4])]
extract_sift(images[0], cfg)
digest = hashlib.sha256()
r0, t0 = resource.getrusage(resource.RUSAGE_SELF), time.perf_counter()
for rgb in images:
    kp, desc = extract_sift(rgb, cfg)
    digest.update(np.ascontiguousarray(kp).tobytes() + np.ascontiguousarray(desc).tobytes())
r1, t1 = resource.getrusage(resource.RUSAGE_SELF), time.perf_counter()
n = len(images)
print(json.dumps({"kept": bool(keep), "frames": n, "wall_ms": 1000 * (t1 - t0) / n,
                  "user_ms": 1000 * (r1.ru_utime - r0.ru_utime) / n, "system_ms": 1000 * (r1.ru_stime - r0.ru_stime) / n,
                  "minor_faults": (r1.ru_minflt - r0.ru_minflt) / n, "features": digest.hexdigest()}))
"""


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--frames", default="runs/kitchen/frames", help="a frame folder (any layout plan --frames reads)")
    ap.add_argument("--step", type=int, default=10, help="every N-th frame")
    ap.add_argument("--count", type=int, default=30, help="at most this many frames")
    args = ap.parse_args()
    runs = {}
    for name, keep in (("default", "0"), ("kept", "1")):
        out = subprocess.run([sys.executable, "-c", CHILD, keep, args.frames, str(args.step), str(args.count)],
                             capture_output=True, text=True, check=True)
        runs[name] = json.loads(out.stdout.strip().splitlines()[-1])
        for key in ("frames", "wall_ms", "user_ms", "system_ms", "minor_faults"):
            emit(f"{name}.{key}", runs[name][key])
    emit("kept_in_effect", runs["kept"]["kept"])
    emit("speedup.wall", runs["default"]["wall_ms"] / runs["kept"]["wall_ms"])
    emit("speedup.cpu", (runs["default"]["user_ms"] + runs["default"]["system_ms"])
         / (runs["kept"]["user_ms"] + runs["kept"]["system_ms"]))
    emit("same_features", runs["default"]["features"] == runs["kept"]["features"])
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
