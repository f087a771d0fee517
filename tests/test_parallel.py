"""A forked child computes what this process would, or this process computes it itself."""

from __future__ import annotations

import os
import time

import numpy as np
import pytest

from bcad import parallel
from bcad.parallel import Ahead, can_fork

PARENT = os.getpid()


def _draws(seed: int, count: int) -> tuple[int, np.ndarray]:
    """The process that ran, and draws on a stream of their own."""
    return os.getpid(), np.random.default_rng(seed).standard_normal(count)


def _dies_in_a_child(value: float) -> tuple[int, float]:
    if os.getpid() != PARENT:
        os._exit(7)  # a child killed before it answers
    return os.getpid(), value


def _fails(message: str) -> None:
    raise ValueError(message)


def _sleeps(seconds: float) -> float:
    time.sleep(seconds)
    return seconds


needs_fork = pytest.mark.skipif(not can_fork(), reason="forking is not used on this platform")


@needs_fork
def test_a_child_returns_what_this_process_computes():
    job = Ahead(_draws, 3, 1000)
    pid, draws = job.result()
    assert pid != PARENT  # it ran in the child
    assert np.array_equal(draws, _draws(3, 1000)[1])


@needs_fork
def test_a_child_that_dies_is_replaced_by_this_process():
    pid, value = Ahead(_dies_in_a_child, 2.5).result()
    assert (pid, value) == (PARENT, 2.5)


def test_an_error_in_the_work_reaches_the_caller():
    with pytest.raises(ValueError, match="no closure"):
        Ahead(_fails, "no closure").result()


@needs_fork
def test_a_cancelled_child_stops_at_once():
    job = Ahead(_sleeps, 30.0)
    started = time.perf_counter()
    job.cancel()
    assert time.perf_counter() - started < 5.0
    assert job.process is None


@needs_fork
def test_a_wedged_child_is_given_up_on(monkeypatch):
    monkeypatch.setattr(parallel, "PATIENCE_SECONDS", 0.2)
    job = Ahead(_sleeps, 30.0)
    job.work, job.args = _draws, (1, 3)  # what this process runs instead once it stops waiting
    started = time.perf_counter()
    pid, _ = job.result()
    assert pid == PARENT and time.perf_counter() - started < 5.0


def test_one_core_asked_for_keeps_the_work_in_this_process(monkeypatch):
    monkeypatch.setenv("BCAD_SINGLE_CORE", "1")
    assert not can_fork()
    job = Ahead(_draws, 5, 10)
    assert job.process is None
    pid, draws = job.result()
    assert pid == PARENT and np.array_equal(draws, _draws(5, 10)[1])


@needs_fork
def test_a_child_dies_with_its_parent(tmp_path):
    """A parent killed without its exit handlers (SIGKILL, the out-of-memory killer) leaves no
    child running on."""
    import subprocess
    import sys

    script = tmp_path / "parent.py"
    script.write_text(
        "import os, sys, time\n"
        "from bcad.parallel import Ahead\n"
        "job = Ahead(time.sleep, 60.0)\n"
        "print(job.process.pid, flush=True)\n"
        "os._exit(0)\n"
    )
    run = subprocess.run([sys.executable, str(script)], capture_output=True, text=True, timeout=60)
    pid = int(run.stdout.split()[0])
    deadline = time.monotonic() + 10.0
    while time.monotonic() < deadline and _running(pid):
        time.sleep(0.05)
    assert not _running(pid)


def _running(pid: int) -> bool:
    """Whether the process exists and is not a zombie."""
    try:
        with open(f"/proc/{pid}/stat", encoding="ascii") as stat:
            return stat.read().rsplit(")", 1)[1].split()[0] != "Z"
    except OSError:
        return False


@needs_fork
def test_a_child_ignores_the_host_program_s_sigterm_handler():
    """A host program whose SIGTERM handler does not exit still has its children stopped."""
    import signal

    previous = signal.signal(signal.SIGTERM, lambda *_: None)
    try:
        job = Ahead(_sleeps, 30.0)
        time.sleep(0.2)  # the child has reset its handlers
        started = time.perf_counter()
        job.cancel()
        assert time.perf_counter() - started < 1.0  # SIGTERM sufficed: no second's wait for SIGKILL
    finally:
        signal.signal(signal.SIGTERM, previous)


def test_a_container_quota_below_two_cores_counts_as_one(tmp_path):
    limits = tmp_path / "cpu.max"
    for text, cores in [
        ("50000 100000\n", 0.5),
        ("200000 100000\n", 2.0),
        ("max 100000\n", float("inf")),
        ("", float("inf")),
    ]:
        limits.write_text(text)
        assert parallel._cgroup_cores(str(limits)) == cores
    assert parallel._cgroup_cores(str(tmp_path / "none")) == float("inf")


@needs_fork
def test_leaving_a_with_block_stops_the_child():
    with pytest.raises(KeyError), Ahead(_sleeps, 30.0) as job:
        raise KeyError("the caller failed")
    assert job.process is None


def _rounds(seed: int, count: int, die_after: int | None = None):
    """Draws in rounds, each with the process that made it; a child dies after ``die_after``."""
    rng = np.random.default_rng(seed)
    for k in range(count):
        if die_after is not None and k == die_after and os.getpid() != PARENT:
            os._exit(7)
        time.sleep(0.2 * (k == 1))  # the second round comes later than the first
        yield os.getpid(), rng.standard_normal(5)


@needs_fork
def test_a_streaming_child_sends_each_value_as_it_comes():
    started = time.perf_counter()
    with Ahead(_rounds, 4, 3, stream=True) as job:
        items = job.items()
        pid, first = next(items)
        first_seconds = time.perf_counter() - started
        rest = list(items)
    all_seconds = time.perf_counter() - started
    expected = [draws for _, draws in _rounds(4, 3)]
    assert pid != PARENT and len(rest) == 2 and all(p == pid for p, _ in rest)
    assert all(np.array_equal(a, b) for a, b in zip([first] + [d for _, d in rest], expected))
    assert all_seconds - first_seconds > 0.15  # the first came before the second round's 0.2 s


@needs_fork
def test_a_streaming_child_that_dies_is_continued_by_this_process():
    got = list(Ahead(_rounds, 5, 4, 2, stream=True).items())
    expected = [draws for _, draws in _rounds(5, 4)]
    # the first from the child; the second it may not have sent before it died; the rest from here
    assert got[0][0] != PARENT and [pid for pid, _ in got[2:]] == [PARENT, PARENT]
    assert all(np.array_equal(a, b) for (_, a), b in zip(got, expected))


def test_a_stream_without_a_child_is_computed_here_when_asked(monkeypatch):
    monkeypatch.setattr(parallel, "can_fork", lambda: False)
    got = list(Ahead(_rounds, 6, 3, stream=True).items())
    assert [pid for pid, _ in got] == [PARENT] * 3


def test_a_streaming_child_whose_parent_stopped_reading_stops_quietly(monkeypatch):
    """The parent closes its end of the pipe when it no longer wants a child's items (it stops
    the child): the child's sender sees the pipe broken, and neither prints a traceback nor keeps
    computing items nobody reads."""
    import multiprocessing
    import threading

    raised = []
    monkeypatch.setattr(threading, "excepthook", lambda arguments: raised.append(arguments.exc_type))
    reader, writer = multiprocessing.get_context("fork").Pipe(duplex=False)
    reader.close()
    computed = []

    def items():
        for k in range(100):
            computed.append(k)
            time.sleep(0.01)
            yield np.zeros(1000)

    parallel._stream(items(), writer)
    assert raised == []
    assert len(computed) < 20  # it stopped soon after its first item found the pipe broken
