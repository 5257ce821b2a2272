"""How well does ``markerplace check --photos`` find where the tags went? Measures it against
the truth on built-in scenes.

Per scene: ``markerplace plan SCENE -k 10`` (1 m lattice, 2 yaws, 0.5 m candidate spacing); per
error set of :data:`markerplace.testbed.photo_walk.ERROR_SETS` (``mixed``: shifts of 2 and 30
cm, turns of 90 and 180 deg, a swapped pair, a missing and an extra tag; ``small``: shifts of
3-10 cm and an extra tag; ``turned``: turns of 180 and -90 deg, a swap, a missing tag, a 18 cm
shift): the tags hung so, photographed by the simulated walk
(:func:`~markerplace.testbed.photo_walk.photo_poses`, 1024 x 768, 66 deg, blur / noise /
exposure in turn), then ``check --photos`` on a cold cache. Printed per run: photos, statuses
right of all planned spots and extras, tags not measured, the recovered tags' position error
(median, 90th percentile, max, cm) and rotation error (median, max, deg) against where they
hang, and the check's wall time per photo (detection, solve and the check itself, one process).

    .venv/bin/python benchmarks/photo_check.py [--scenes tiny,room,studio,apartment,house] \\
        [--sets mixed,small,turned] [--out DIR]
"""

from __future__ import annotations

import argparse
import json
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT / "src"))

from markerplace.cli.main import main  # noqa: E402
from markerplace.localization.tag_anchor import rotation_deg  # noqa: E402
from markerplace.plan.discretize.artifact import load  # noqa: E402
from markerplace.plan.folder import read_plan_folder  # noqa: E402
from markerplace.runtime.atomic_io import write_image, write_json  # noqa: E402
from markerplace.scan.frameset import intrinsics_dict  # noqa: E402
from markerplace.testbed import photo_walk  # noqa: E402


def run(scene: str, sets: list[str], out: Path) -> list[dict]:
    plan = out / scene / "plan"
    if not (plan / "placement.json").exists():
        assert main(["--quiet", "plan", scene, "-k", "10", "--grid-spacing", "1.0", "--yaws", "2", "--marker-spacing",
                     "0.5", "--out", str(plan)]) == 0
    folder = read_plan_folder(plan)
    world = folder.spec.load()
    planned = list(folder.markers)
    cands = load(plan / "discretization.npz").candidate_world_from_marker
    rows = []
    for name in sets:
        hung, status, truth = photo_walk.hang(planned, photo_walk.ERROR_SETS[name], cands, world)
        spots = [m.world_from_marker for m in hung] + [planned[o - 1].world_from_marker for o, s in status.items()
                                                        if s == "missing"]
        poses = photo_walk.photo_poses(world, spots, planned[0].size, np.random.default_rng(0))
        work = out / scene / name
        (work / "photos").mkdir(parents=True, exist_ok=True)
        for k, rgb in enumerate(photo_walk.take_photos(world, hung, poses)):
            write_image(work / "photos" / f"IMG_{k:03d}.png", rgb)
        write_json(work / "phone.json", intrinsics_dict(photo_walk.PHONE, 1000.0))
        t0 = time.perf_counter()
        code = main(["--quiet", "check", str(plan), "--photos", str(work / "photos"), "--intrinsics",
                     str(work / "phone.json"), "--out", str(work / "check")])
        seconds = time.perf_counter() - t0
        if code != 0:
            rows.append({"scene": scene, "set": name, "photos": len(poses), "error": f"exit {code} (the error above)"})
            print(_line(rows[-1]), flush=True)
            continue
        report = json.loads((work / "check" / "check.json").read_text())
        expected = {**{o: s for o, s in status.items()}, **{None: "extra"}}
        right = sum(r["status"] == expected.get(r["order"]) for r in report["tags"])
        dpos, drot = [], []
        for r in report["tags"]:
            if r["installed_id"] is not None and r["installed_world_from_marker"] is not None:
                Q, T = np.array(r["installed_world_from_marker"]), truth[r["installed_id"]]
                dpos.append(100 * float(np.linalg.norm(Q[:3, 3] - T[:3, 3])))
                drot.append(rotation_deg(Q, T))
        dpos, drot = dpos or [np.nan], drot or [np.nan]  # nothing measured
        rows.append({"scene": scene, "set": name, "photos": len(poses), "right": right, "rows": len(report["tags"]),
                     "not_measured": sum(r["status"] == "not measured" for r in report["tags"]),
                     "pos_med": float(np.median(dpos)), "pos_p90": float(np.percentile(dpos, 90)),
                     "pos_max": float(np.max(dpos)), "rot_med": float(np.median(drot)), "rot_max": float(np.max(drot)),
                     "s_per_photo": seconds / len(poses)})
        print(_line(rows[-1]), flush=True)
    return rows


HEADER = ("| scene | errors | photos | statuses right | not measured | position error cm: median / p90 / max "
          "| rotation error deg: median / max | s per photo |\n|---|---|---|---|---|---|---|---|")


def _line(r: dict) -> str:
    if "error" in r:
        return f"| {r['scene']} | {r['set']} | {r['photos']} | {r['error']} | | | | |"
    return (f"| {r['scene']} | {r['set']} | {r['photos']} | {r['right']} / {r['rows']} | {r['not_measured']} | "
            f"{r['pos_med']:.2f} / {r['pos_p90']:.2f} / {r['pos_max']:.2f} | {r['rot_med']:.2f} / {r['rot_max']:.2f} | "
            f"{r['s_per_photo']:.2f} |")


def cli() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--scenes", default="tiny,room,studio,apartment,house")
    ap.add_argument("--sets", default="mixed,small,turned")
    ap.add_argument("--out", default=None, help="keep plans, photos and checks here (default: a temporary folder)")
    args = ap.parse_args()
    out = Path(args.out) if args.out else Path(tempfile.mkdtemp(prefix="photo_check_"))
    print(HEADER, flush=True)
    rows = []
    for scene in args.scenes.split(","):
        rows += run(scene, args.sets.split(","), out)
    ok = [r for r in rows if "error" not in r]
    if ok:
        print(f"\nall runs: statuses right {sum(r['right'] for r in ok)} / {sum(r['rows'] for r in ok)}, worst position "
              f"error {np.nanmax([r['pos_max'] for r in ok]):.2f} cm, worst rotation error "
              f"{np.nanmax([r['rot_max'] for r in ok]):.2f} "
              f"deg, {np.median([r['s_per_photo'] for r in ok]):.2f} s per photo (median)")


if __name__ == "__main__":
    cli()
