"""`evaluate` works the same on a mesh file written by `scene export` as on the built-in name."""

import csv

from helpers import FAST
from markerplace.cli.main import main


def test_evaluate_on_exported_glb_matches_builtin(tmp_path):
    glb = tmp_path / "tiny.glb"
    assert main(["scene", "export", "tiny", str(glb)]) == 0
    common = ["--tests", "12", "--k", "1", "--runs", "1", "--methods", "none,omp", "--test-sets", "weighted", *FAST]
    assert main(["evaluate", str(glb), "--out", str(tmp_path / "glb"), *common]) == 0
    assert main(["evaluate", "tiny", "--out", str(tmp_path / "builtin"), *common]) == 0
    rows = {name: list(csv.DictReader((tmp_path / name / "recall.csv").open())) for name in ("glb", "builtin")}
    key = lambda r: (r["method"], r["k"], r["threshold"])  # noqa: E731
    assert sorted(map(key, rows["glb"])) == sorted(map(key, rows["builtin"]))
    assert {(r["method"], r["k"]) for r in rows["glb"]} == {("none", "0"), ("omp", "1")}
    # same geometry within 1 mm and same textures: same test poses and the same recall
    by_key = {key(r): float(r["recall"]) for r in rows["builtin"]}
    for r in rows["glb"]:
        assert abs(float(r["recall"]) - by_key[key(r)]) <= 1.0 / 12 + 1e-9
