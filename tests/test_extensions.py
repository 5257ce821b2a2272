"""Every extension point takes a new part through its registry alone (docs/contributing.md,
"Adding a part"): one toy of each kind is registered here, nothing else of markerplace is
touched, and ``plan`` and ``evaluate`` run with them on the smallest scene.

The toys run in this process (``--workers 1``): a part registered in a test is not registered in
a spawned worker (a real part registers where its module is imported).
"""

from __future__ import annotations

import csv
import json
from dataclasses import dataclass

import numpy as np
import pytest

from markerplace.cli.main import main
from markerplace.localization.localizer import LOCALIZERS, LocalizationResult, Localizer, LocalizerSettings
from markerplace.plan.place.greedy import apply_coverages
from markerplace.plan.place.methods import PLACEMENT_METHODS, CalibratedMethod, CalibrationConfig, Choice, PlacementMethod
from markerplace.plan.score.marker_models import MARKER_MODELS, MarkerModel
from markerplace.report.output_files import OUTPUT_FILES, OutputFile
from markerplace.report.tagmaps.format import TAG_MAP_FORMATS, TagMapFormat
from markerplace.settings import setting
from markerplace.simulation.conditions import CONDITIONS, Condition

FAST = ["--grid-spacing", "2.0", "--yaws", "2", "--workers", "1", "--quiet"]


def _order_choice(data, order) -> Choice:
    order = np.asarray(order, dtype=np.int64)
    return Choice(order, np.full(len(order), np.nan), float("nan"),
                  apply_coverages(data.base_info, [data.coverages[i] for i in order]))


class ToyLast(PlacementMethod):
    """The last k candidates, skipping the last ``skip``."""

    name, summary, label = "toy-last", "last candidates first", "Last"

    @dataclass(frozen=True)
    class Config:
        skip: int = setting(0, bounds=(0, 100), hint="a number of candidates, e.g. 1")

    default_conf = Config()

    def place(self, data, k, seed=0, progress=False, target=None):
        C = data.num_candidates
        return _order_choice(data, np.arange(C - 1 - self.conf.skip, C - 1 - self.conf.skip - k, -1))


class ToySure(CalibratedMethod):
    """The k candidates seen by most poses whose fitted success probability is lowest."""

    name, summary, label = "toy-sure", "most-seen candidates where the fit says it fails", "Sure"
    nested = True

    @dataclass(frozen=True)
    class Config(CalibrationConfig):
        pass

    default_conf = Config(calibration_runs=0)
    fitted: list = []

    def place(self, data, k, seed=0, progress=False, target=None):
        fit = self.fit(data)  # the model calibrate_plan fitted with this method's CalibrationConfig
        ToySure.fitted.append(fit["model"])
        seen = [len(c.pose_idx) for c in fit["coverages"][:data.num_candidates]]
        return _order_choice(data, np.argsort(-np.asarray(seen), kind="stable")[:k])


class ToyHalf(MarkerModel):
    """Half the paper model's information."""

    name, summary = "toy-half", "half the paper's information"

    def information(self, world_from_cam, world_from_marker, size, K):
        return 0.5 * MARKER_MODELS["paper"](self.noise).information(world_from_cam, world_from_marker, size, K)


class ToyNearest(Localizer):
    """The pose of the map image of highest VLAD similarity (no matching at all)."""

    name, summary = "toy-nearest", "the most similar map image's pose"
    calls: list = []

    @dataclass(frozen=True)
    class Config(LocalizerSettings):
        pass

    default_conf = Config()

    def localize_features(self, keypoints, descriptors, tags, exclude=None):
        ToyNearest.calls.append(len(keypoints))
        sims = self.db.vlad @ self.db.codebook.vlad(np.asarray(descriptors, np.float32))
        if exclude is not None and len(exclude):
            sims[np.asarray(exclude, np.int64)] = -np.inf
        best = int(np.argmax(sims))
        return LocalizationResult(self.db.poses[best].copy(), 0, [best], [d.tag_id for d in tags], 0, {})


class ToyList(TagMapFormat):
    """One line per tag: id x y z."""

    name, summary, file = "toy-list", "tag id and position", "toy_tags.txt"

    @staticmethod
    def text(markers, context):
        return "".join(f"{m.tag_id} {' '.join(f'{v:.3f}' for v in m.world_from_marker[:3, 3])}\n" for m in markers)


class ToyDim(Condition):
    """Every pixel at 90 %."""

    name, summary = "toy-dim", "10 % darker"

    @dataclass(frozen=True)
    class Config:
        factor: float = 0.9

    default_conf = Config()

    def filter(self, rgb, params, rng, depth=None, K=None):
        return (rgb.astype(np.float32) * self.conf.factor).astype(np.uint8)


class ToyCount(OutputFile):
    """How many tags the plan placed."""

    name, summary, file = "toy-count", "the number of tags", "toy_count.txt"

    def write(self, path, outputs):
        path.write_text(f"{len(outputs.records)} tags by {outputs.method}\n")


TOYS = [(PLACEMENT_METHODS, ToyLast), (PLACEMENT_METHODS, ToySure), (MARKER_MODELS, ToyHalf),
        (LOCALIZERS, ToyNearest), (TAG_MAP_FORMATS, ToyList), (CONDITIONS, ToyDim), (OUTPUT_FILES, ToyCount)]


@pytest.fixture
def toys():
    """Each toy registered for the test only (the registries are all it touches)."""
    for registry, cls in TOYS:
        registry.register(cls)
    try:
        yield
    finally:
        for registry, cls in TOYS:
            registry.pop(cls.name, None)


def test_toy_parts_run_through_plan(toys, tmp_path, capsys):
    out = tmp_path / "plan"
    assert main(["plan", "tiny", "-k", "2", "--method", "toy-last", "--method-conf", "skip=1",
                 "--marker-model", "toy-half", "--out", str(out), *FAST]) == 0
    doc = json.loads((out / "placement.json").read_text())
    cands = [m["candidate_index"] for m in doc["markers"]]
    C = doc["summary"]["num_candidates"]
    assert doc["method"] == "toy-last" and cands == [C - 2, C - 3]  # its own setting (skip=1) reached it
    config = json.loads((out / "config.json").read_text())
    assert config["placement"]["methods"]["toy_last"] == {"skip": 1}
    assert config["placement"]["marker_model"] == "toy-half"
    lines = (out / "tagmaps" / "toy_tags.txt").read_text().splitlines()
    assert [int(line.split()[0]) for line in lines] == [0, 1]
    assert (out / "toy_count.txt").read_text() == "2 tags by toy-last\n"

    # a bad key of the method: one line naming its keys
    assert main(["plan", "tiny", "--method", "toy-last", "--method-conf", "skips=1", "--out", str(out), *FAST]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "toy-last has no setting 'skips': its settings are skip" in err[0]

    # a calibrated toy, the recall model of its plan (a --config file sets it)
    toml = tmp_path / "sure.toml"
    toml.write_text('[placement]\nrecall_model = "toy-sure"\n[placement.methods.toy_sure]\ncalibration_k = 2\n')
    sure = tmp_path / "sure"
    ToySure.fitted.clear()
    assert main(["plan", "tiny", "-k", "2", "--method", "toy-sure", "--config", str(toml), "--out", str(sure),
                 *FAST]) == 0
    assert len(ToySure.fitted) == 1 and (sure / "success_model_toy-sure.json").exists()
    assert not (sure / "success_model_expected-recall.json").exists()  # the plan's recall model is the toy's
    predicted = json.loads((sure / "placement.json").read_text())["predicted_recall"]
    model = ToySure.fitted[0]  # placement.json's copy is rounded
    assert predicted["available"] and predicted["model"]["slope"] == pytest.approx(model.slope, rel=1e-9)


def test_toy_parts_run_through_evaluate(toys, tmp_path):
    out = tmp_path / "eval"
    ToyNearest.calls.clear()
    ToySure.fitted.clear()
    assert main(["evaluate", "tiny", "--out", str(out), "--tests", "10", "--k", "2", "--runs", "1",
                 "--methods", "none,toy-last,toy-sure", "--method-conf", "toy-last.skip=2", "--marker-model", "toy-half",
                 "--localizer", "toy-nearest", "--conditions", "toy-dim", "--test-sets", "uniform", *FAST]) == 0
    assert ToyNearest.calls  # the toy localized the test images
    assert len(ToySure.fitted) == 1  # placed with the model evaluate's calibration fitted
    rows = list(csv.DictReader((out / "recall.csv").open()))
    assert {r["method"] for r in rows} == {"none", "toy-last", "toy-sure"}
    assert all(r["condition"] == "toy-dim" for r in rows) and all(0.0 <= float(r["recall"]) <= 1.0 for r in rows)
    config = json.loads((out / "config.json").read_text())
    assert config["plan"]["placement"]["methods"]["toy_last"] == {"skip": 2}
    assert config["evaluate"]["localization"]["localizer"] == "toy-nearest"
