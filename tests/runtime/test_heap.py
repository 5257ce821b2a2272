"""Freed memory kept for the next image (runtime/heap.py): against glibc's real allocator, in
fresh processes (the setting lasts for a process's life)."""

from __future__ import annotations

import subprocess
import sys

import pytest

from markerplace.runtime.heap import MMAP_THRESHOLD, TRIM_THRESHOLD

ROUNDS = """
import resource, sys
import numpy as np
from markerplace.runtime.heap import keep_freed_memory
if sys.argv[1] == "1":
    assert keep_freed_memory() and keep_freed_memory()  # in effect, and a second call is harmless
def one_image():  # a SIFT-like pattern: many large blocks, all freed at the end
    blocks = [np.ones(6 * 2**20 // 8) for _ in range(12)]  # 72 MB in 6 MB blocks, every page written
    del blocks
one_image(); one_image()
before = resource.getrusage(resource.RUSAGE_SELF).ru_minflt
for _ in range(3):
    one_image()
print((resource.getrusage(resource.RUSAGE_SELF).ru_minflt - before) / 3)
"""


def test_thresholds_are_values_glibc_accepts():
    assert MMAP_THRESHOLD <= 32 * 2**20  # glibc's largest M_MMAP_THRESHOLD on 64-bit (else mallopt refuses it)
    assert TRIM_THRESHOLD >= 72 * 2**20  # more than a SIFT call frees at once, or it is trimmed anyway


def _faults_per_round(keep: bool) -> float:
    out = subprocess.run([sys.executable, "-c", ROUNDS, "1" if keep else "0"], capture_output=True, text=True,
                         check=True)
    return float(out.stdout.strip())


@pytest.mark.skipif(not sys.platform.startswith("linux"), reason="glibc's mallopt; elsewhere nothing is changed")
def test_kept_memory_is_reused_without_page_faults():
    default, kept = _faults_per_round(False), _faults_per_round(True)
    assert default > 3000  # glibc gives the 72 MB back and faults it in again (18,432 pages of 4 kB)
    assert kept < 100
