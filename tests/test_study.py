"""`markerplace study`: the parameter and sensitivity study of one scene, end to end on tiny."""

from __future__ import annotations

import csv

from markerplace.cli.main import main

SMALL = ["--grid-spacing", "1.0", "--yaws", "4", "--workers", "1", "--quiet"]


def test_study_tiny_writes_every_group_with_paired_differences(tmp_path, capsys):
    out = tmp_path / "study"
    args = ["study", "tiny", "--out", str(out), "--tests", "10", "--k", "2", "--vs", "50", "--shifts", "0.25",
            "--scales", "0.5", *SMALL]
    assert main(args) == 0
    md = (out / "study.md").read_text()
    for heading in ("## v", "## detection", "## test data", "## similarity", "## shift", "## size"):
        assert heading in md, heading
    for row in ("v = 50", "tag detection off", "uniform test data", "similarity analysis off", "shifted +-0.25 m",
                "printed x0.5"):
        assert f"| {row} |" in md, row
    assert md.count("| (minus default) |") == 5  # every paired row; uniform test data has other images
    rows = list(csv.DictReader((out / "study.csv").open()))
    assert {r["group"] for r in rows} == {"v", "detection", "test data", "similarity", "shift", "size"}
    assert all(0.0 <= float(r["recall"]) <= 1.0 and r["n_tests"] == "10" for r in rows)
    for group in ("v", "detection", "test_data", "similarity", "shift", "size"):
        assert (out / f"study_{group}.png").stat().st_size > 0
    # one work folder: the plan and the marker-free images are computed once for every run
    assert (out / "work" / "plan" / "observations").is_dir() and not (out / "runs" / "default" / "plan").exists()
    assert sorted(p.name for p in (out / "runs").iterdir()) == ["default", "no-detection", "shift-0.25", "size-0.5"]
    assert "# Parameter and sensitivity study" in capsys.readouterr().out
