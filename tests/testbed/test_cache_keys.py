"""An evaluation's caches are keyed by what each result reads, not by what else the run
evaluates: adding a method (or ``--ceiling``, or a placement file) to an evaluation in the same
folder localizes only the new placements. Every image set's in-view mask has a column per
marker of *every* evaluated placement, so a key that held the whole mask (as before) changed
with each new placement and re-localized everything."""

from __future__ import annotations

import json
from dataclasses import replace

from markerplace.pipelines.evaluate import run_evaluation
from markerplace.plan.config import PlanConfig
from markerplace.plan.discretize.stage import DiscretizeConfig
from markerplace.runtime.executor import RuntimeConfig
from markerplace.scene.spec import SceneSpec
from markerplace.testbed import config as tbconfig


def _predictions(out) -> dict:
    """prediction file -> (its method, its bytes)."""
    files = sorted((out / "cache" / "predictions").glob("*.npz"))
    return {p.name: (json.loads(p.with_name(p.name + ".meta.json").read_text())["method"], p.read_bytes()) for p in files}


def test_adding_a_method_localizes_only_the_new_placements(tmp_path):
    plan = PlanConfig(discretize=replace(DiscretizeConfig(), grid_spacing=1.0, num_yaws=2), runtime=RuntimeConfig(workers=1))
    first = tbconfig.EvaluateConfig(test=tbconfig.TestSetConfig(tests=12, sets=("weighted",)),
                                    study=tbconfig.StudyConfig(methods=("none", "omp"), runs=1, ks=(2,)))
    run_evaluation(SceneSpec("tiny"), plan, first, tmp_path, progress=False)
    before = _predictions(tmp_path)
    assert sorted(m for m, _ in before.values()) == ["none", "omp"]
    codebook = (tmp_path / "cache" / "vlad_codebook.npz").stat().st_mtime_ns

    more = replace(first, study=replace(first.study, methods=("none", "omp", "random")))
    run_evaluation(SceneSpec("tiny"), plan, more, tmp_path, progress=False)
    after = _predictions(tmp_path)
    assert {k: v for k, v in after.items() if k in before} == before  # every earlier result kept, unchanged
    assert sorted(m for k, (m, _) in after.items() if k not in before) == ["random"]
    assert (tmp_path / "cache" / "vlad_codebook.npz").stat().st_mtime_ns == codebook  # the map's codebook too
