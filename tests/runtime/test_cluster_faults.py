"""A Dask cluster that has no workers, loses them or loses its scheduler: real ``dask scheduler``
and ``dask worker`` processes on 127.0.0.1, killed on purpose (SIGKILL).

* no worker: ``plan --cluster ADDR`` waits ``--cluster-wait`` seconds with a log line, then one
  line, exit 2 (it waited without end);
* one of two workers killed mid-map: Dask runs its tasks on the other, every result arrives;
* the only worker killed: a worker that joins within the wait takes over; when none does, one
  line after the wait, with the results that finished handed out first (a stage writes them);
* the scheduler killed mid-plan: one line naming its address and how to resume, exit 2, the
  finished stage kept (it was a ``FutureCancelledError`` traceback, exit 1).
"""

from __future__ import annotations

import faulthandler
import subprocess
import sys
import time

import pytest

from helpers.dask_processes import DaskProcesses, build, env, slow_double
from markerplace.cli.main import main
from markerplace.errors import UserError
from markerplace.runtime.cluster_watch import POLL_S, running_threads
from markerplace.runtime.executor import DaskExecutor, WorkerJob

SMALL = ["--grid-spacing", "1.0", "--yaws", "2"]
JOB = WorkerJob(build=build, spec=0.4, key="slow-double")


@pytest.fixture(autouse=True)
def no_endless_hang():
    """The maps below run in this process: should one hang (as a lost cluster made it before),
    the test process ends after 5 minutes with every thread's traceback instead."""
    faulthandler.dump_traceback_later(300, exit=True)
    yield
    faulthandler.cancel_dump_traceback_later()


def _wait_for_threads(ex: DaskExecutor, n: int, timeout_s: float = 60.0) -> None:
    deadline = time.monotonic() + timeout_s
    while running_threads(ex.client) != n:
        assert time.monotonic() < deadline, f"fewer than {n} workers joined in {timeout_s:g} s"
        time.sleep(0.2)


def _one_line(err: str) -> str:
    lines = [ln for ln in err.strip().splitlines() if ln.strip()]
    assert len(lines) == 1, err[-3000:]
    assert lines[0].startswith("markerplace: error: --cluster "), lines[0]
    return lines[0]


@pytest.mark.parametrize("argv, needle", [
    (["--cluster-wait", "5"], "--cluster-wait 5 has no effect without --cluster"),
    (["--cluster", "local:1", "--cluster-wait", "-1"], "--cluster-wait -1 s is outside [0, 86400] s"),
])
def test_cluster_wait_is_checked(argv, needle, tmp_path, capsys):
    assert main(["plan", "tiny", "--out", str(tmp_path / "p"), *argv]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and needle in err[0], err


def _plan(out, address: str, *options: str) -> subprocess.Popen:
    """``markerplace plan tiny -k 2 --out OUT --cluster ADDRESS`` (small) in a subprocess: a hang
    there is a failed test (its timeout), not a suite that never ends."""
    return subprocess.Popen([sys.executable, "-m", "markerplace.cli", "plan", "tiny", "-k", "2", "--out", str(out),
                             "--cluster", address, *options, *SMALL], env=env(), stdout=subprocess.PIPE,
                            stderr=subprocess.PIPE, text=True)


def test_a_scheduler_without_workers_is_one_line_after_the_wait(tmp_path):
    with DaskProcesses(tmp_path / "dask") as dask:
        t0 = time.monotonic()
        plan = _plan(tmp_path / "p", dask.address, "--cluster-wait", "2")
        try:
            _, err = plan.communicate(timeout=120)
        finally:
            if plan.poll() is None:
                plan.kill()
        elapsed = time.monotonic() - t0
    assert plan.returncode == 2, err[-3000:]
    assert f"dask: no worker at {dask.address}; waiting for one to join (0 of 2 s, --cluster-wait)" in err
    last = err.strip().splitlines()[-1]
    assert last.startswith(f"markerplace: error: --cluster {dask.address}: no Dask worker joined the scheduler "
                           "within 2 s; start workers with `dask worker"), last
    assert "Traceback" not in err and elapsed < 60


def test_the_tasks_of_a_killed_worker_run_on_the_other(tmp_path):
    with DaskProcesses(tmp_path / "dask") as dask:
        a, b = dask.worker(), dask.worker()
        with DaskExecutor(dask.address, batch=1, cluster_wait=5) as ex:
            _wait_for_threads(ex, 2)
            got, pids_after = {}, set()
            for i, (value, pid) in ex.map(slow_double, list(range(12)), JOB):
                got[i] = value
                if len(got) == 2:
                    dask.kill(a)  # it holds a task (Dask hands each worker one or two at a time)
                elif len(got) > 4:
                    pids_after.add(pid)
            assert got == {i: 2 * i for i in range(12)}
            assert pids_after == {b.pid}


def test_when_every_worker_is_gone_the_wait_is_bounded(tmp_path):
    with DaskProcesses(tmp_path / "dask") as dask:
        first = dask.worker()
        with DaskExecutor(dask.address, batch=1, cluster_wait=60) as ex:
            _wait_for_threads(ex, 1)
            # the only worker killed, another joins within the wait: it takes over
            got = {}
            for i, (value, _) in ex.map(slow_double, list(range(6)), JOB):
                got[i] = value
                if len(got) == 1:
                    dask.kill(first)
                    second = dask.worker()
            assert got == {i: 2 * i for i in range(6)}
            # killed too, and none joins: one line after the wait, the finished results handed out first
            ex.cluster_wait = 1.5
            got = {}
            with pytest.raises(UserError) as err:
                for i, (value, _) in ex.map(slow_double, list(range(6)), JOB):
                    got[i] = value
                    if len(got) == 1:
                        dask.kill(second)
                        t_kill = time.monotonic()
            waited = time.monotonic() - t_kill
    assert got and all(v == 2 * i for i, v in got.items())
    msg = str(err.value)
    assert msg.startswith(f"--cluster {dask.address}: every Dask worker left and none joined within 1.5 s "
                          f"({len(got)} of 6 tasks finished); start workers with `dask worker {dask.address}"), msg
    assert "re-run the same command" in msg
    assert 1.5 <= waited < 1.5 + POLL_S + 15


def test_a_lost_scheduler_is_one_line_naming_it(tmp_path):
    out = tmp_path / "p"
    with DaskProcesses(tmp_path / "dask") as dask:
        dask.worker()
        plan = _plan(out, dask.address, "--quiet")
        try:
            deadline = time.monotonic() + 120
            while not (out / "observations").exists():  # the observe stage started on the cluster
                assert plan.poll() is None and time.monotonic() < deadline, plan.communicate()[1][-3000:]
                time.sleep(0.05)
            dask.kill(dask.scheduler)
            _, err = plan.communicate(timeout=120)
        finally:
            if plan.poll() is None:
                plan.kill()
    assert plan.returncode == 2, err[-3000:]
    line = _one_line(err)
    assert line.startswith(f"markerplace: error: --cluster {dask.address}: lost the connection to the Dask "
                           "scheduler ("), line
    assert f"to resume, start the scheduler and its workers again at {dask.address} and re-run the same command" in line
    assert (out / "discretization.npz").is_file()  # the finished stage is kept for the resume
