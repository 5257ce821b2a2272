"""The reports' 3D view (report/view3d.py) on room, house and a scan-like house: how big the HTML
gets and how long it takes to build, to open in headless chromium (software WebGL, no GPU) and to
draw a frame while orbiting.

Prints ``name: value`` lines per scene: the model's faces and the view's triangles, the seconds
to build the fragment (decimation included), the page's size in MB (goal: under 20 MB for the
scan), the seconds from ``driver.get`` to the first frame drawn, and the mean milliseconds per
orbit frame (20 frames, then one pixel read back so the GPU work is finished).

    .venv/bin/python benchmarks/view3d.py [--scenes room,house,house-scan] [--work out/bench_view3d]

``house-scan`` is ``scene export house --as-scan`` (cached in ``--work``; about 5 min to make),
loaded with ``--up z``. The tags: four per room (built-in rooms; the scan uses the house's), on
the walls hit by horizontal rays from the room's centre 1.5 m above its floor.
"""

from __future__ import annotations

import argparse
import subprocess
import sys
import time
from pathlib import Path

import numpy as np

from markerplace.geometry import world_from_marker_pose
from markerplace.markers import Marker
from markerplace.report.html import write_page
from markerplace.report.view3d import scene_view_html
from markerplace.scene import load_scene
from markerplace.scene.raycast import RayCaster

GOAL_MB = 20.0


def emit(name: str, value) -> None:
    if isinstance(value, float):
        value = f"{value:.4g}"
    print(f"{name}: {value}", flush=True)


def room_tags(scene, rooms) -> list:
    rc = RayCaster(*scene.geometry())
    o, d = [], []
    for r in rooms:
        x0, y0, x1, y1 = r.bounds
        for a in (0.0, 90.0, 180.0, 270.0):
            o.append([(x0 + x1) / 2, (y0 + y1) / 2, r.floor_z + 1.5])
            d.append([np.cos(np.radians(a)), np.sin(np.radians(a)), 0.0])
    o, d = np.array(o), np.array(d)
    t, _ = rc.first_hits(o, d, max_t=20.0)
    return [Marker(i, 0.3, world_from_marker_pose(o[i] + t[i] * d[i], -d[i])) for i in range(len(o)) if np.isfinite(t[i])]


def load(name: str, work: Path):
    if name != "house-scan":
        scene = load_scene(name)
        return scene, scene.rooms
    scan = work / "house_scan.ply"
    if not scan.is_file():
        work.mkdir(parents=True, exist_ok=True)
        subprocess.run([sys.executable, "-m", "markerplace.cli", "--quiet", "scene", "export", "house", str(scan),
                        "--as-scan"], check=True)
    return load_scene(str(scan), up="z"), load_scene("house").rooms


def browser():
    from selenium import webdriver
    from selenium.webdriver.chrome.service import Service

    opts = webdriver.ChromeOptions()
    opts.binary_location = "/usr/bin/chromium"
    for arg in ("--headless=new", "--no-sandbox", "--disable-gpu", "--disable-dev-shm-usage", "--window-size=1280,1000"):
        opts.add_argument(arg)
    return webdriver.Chrome(service=Service("/usr/bin/chromedriver"), options=opts)


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--scenes", default="room,house,house-scan")
    ap.add_argument("--work", default="out/bench_view3d")
    args = ap.parse_args()
    work = Path(args.work)
    work.mkdir(parents=True, exist_ok=True)
    driver = browser()
    ok = True
    try:
        for name in args.scenes.split(","):
            scene, rooms = load(name, work)
            tags = room_tags(scene, rooms)
            t = time.perf_counter()
            frag = scene_view_html(scene, tags)
            build = time.perf_counter() - t
            page = write_page(work / f"{name}.html", name, frag)
            mb = page.stat().st_size / 1e6
            t = time.perf_counter()
            driver.get(page.resolve().as_uri())
            frames = driver.execute_script("return window.mpView3d['mp-view3d'].frames")
            opened = time.perf_counter() - t
            frame_ms = driver.execute_script(
                "var v = window.mpView3d['mp-view3d'], t = performance.now();"
                "var r = document.querySelector('#mp-view3d canvas').getBoundingClientRect();"
                "for (var i = 0; i < 20; i++) v.orbit(0.05, 0);"
                "v.pickAt(r.left + r.width / 2, r.top + r.height / 2); return (performance.now() - t) / 20")
            emit(f"{name}.faces", scene.num_faces)
            emit(f"{name}.view_triangles", driver.execute_script("return window.mpView3d['mp-view3d'].triangles"))
            emit(f"{name}.tags", len(tags))
            emit(f"{name}.build_s", build)
            emit(f"{name}.html_mb", mb)
            emit(f"{name}.open_s", opened)
            emit(f"{name}.frames_at_open", frames)
            emit(f"{name}.orbit_frame_ms", float(frame_ms))
            ok &= frames >= 1 and (name != "house-scan" or mb < GOAL_MB)
    finally:
        driver.quit()
    return 0 if ok else 1


if __name__ == "__main__":
    sys.exit(main())
