"""Where the work runs never changes the result: ``plan`` and ``evaluate`` on ``tiny`` in this
process, on a local process pool and on a 2-worker Dask ``LocalCluster`` give byte-identical
``placement.json`` and identical per-query errors."""

from __future__ import annotations

import numpy as np
import pytest

from markerplace.cli.main import main

BACKENDS = {"in-process": ["--workers", "1"], "pool": ["--workers", "2"], "dask": ["--cluster", "local:2"]}
SMALL = ["--grid-spacing", "1.0", "--yaws", "2", "--quiet"]


@pytest.fixture(scope="module")
def runs(tmp_path_factory):
    root = tmp_path_factory.mktemp("backends")
    out = {}
    for name, opts in BACKENDS.items():
        plan, ev = root / f"plan_{name}", root / f"eval_{name}"
        assert main(["plan", "tiny", "-k", "3", "--out", str(plan), *SMALL, *opts]) == 0
        assert main(["evaluate", "tiny", "--out", str(ev), "--tests", "8", "--k", "2", "--runs", "1",
                     "--methods", "none,omp,random", "--test-sets", "weighted", *SMALL, *opts]) == 0
        out[name] = (plan, ev)
    return out


def test_placement_is_byte_identical_on_every_backend(runs):
    ref = (runs["in-process"][0] / "placement.json").read_bytes()
    for name, (plan, _) in runs.items():
        assert (plan / "placement.json").read_bytes() == ref, name


def test_per_query_errors_are_identical_on_every_backend(runs):
    ref = np.load(runs["in-process"][1] / "query_errors.npz")
    assert ref["weighted_t_err"].shape == (3, 8)
    for name, (_, ev) in runs.items():
        got = np.load(ev / "query_errors.npz")
        assert set(got.files) == set(ref.files), name
        for key in ref.files:
            a, b = ref[key], got[key]
            assert np.array_equal(a, b, equal_nan=a.dtype.kind == "f"), (name, key)


def test_unreachable_scheduler_is_a_one_line_error(tmp_path, capsys):
    assert main(["plan", "tiny", "--out", str(tmp_path / "x"), "--cluster", "tcp://127.0.0.1:9", *SMALL]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "Dask scheduler" in err[0]
