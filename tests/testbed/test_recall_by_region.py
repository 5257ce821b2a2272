"""benchmarks/recall_by_region.py: recall split by where the test images are, on a made-up run
folder whose answer is known."""

from __future__ import annotations

import importlib.util

import numpy as np

from helpers import REPO


def _bench():
    spec = importlib.util.spec_from_file_location("recall_by_region", REPO / "benchmarks" / "recall_by_region.py")
    bench = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(bench)
    return bench


def test_recall_by_region_splits_images_by_their_true_position(tmp_path, capsys):
    bench = _bench()
    world_from_cam = np.tile(np.eye(4), (6, 1, 1))
    world_from_cam[:, 0, 3] = [-2, -1, 1, 2, 3, 4]       # two images west of x = 0
    world_from_cam[:, 1, 3] = [0, 9, 9, 9, 0, 0]         # then two north of y = 5 (first match wins)
    np.savez(tmp_path / "test_poses_weighted.npz", world_from_cam=world_from_cam)
    ok, miss = 0.01, 1.0
    t_err = np.array([[ok, miss, ok, ok, miss, miss],    # none: west 1/2, north 2/2, rest 0/2
                      [ok, ok, ok, miss, ok, miss],      # random run 0
                      [ok, ok, miss, miss, ok, ok]])     # random run 1
    np.savez(tmp_path / "query_errors.npz", weighted_method=np.array(["none", "random", "random"]),
             weighted_k=np.array([0, 5, 5]), weighted_t_err=t_err, weighted_r_err=np.zeros_like(t_err))
    assert bench.main([str(tmp_path), "--region", "west:x<0", "--region", "north:y>5", "--rest", "rooms"]) == 0
    out = capsys.readouterr().out
    assert "| west (2 images) | north (2 images) | rooms (2 images) | all |" in out
    assert "| none | 0 | 1 | 50.0 | 100.0 | 0.0 | 50.0 |" in out
    assert "| random | 5 | 2 | 100.0 | 25.0 | 75.0 | 66.7 |" in out
    assert bench.main([str(tmp_path), "--test-set", "uniform"]) == 2
    assert "no test set 'uniform'" in capsys.readouterr().err
