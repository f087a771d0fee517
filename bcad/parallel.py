"""Independent parts of one run computed on a second core, in a forked child process.

A solve's branch search runs independent lineages, each on its own random streams, so the
answer does not depend on where a lineage runs. Threads do not help there: the lineages' numpy
calls are small and the interpreter's lock serialises them (a UR5 cell's branch search: 13.8 s
on one thread, 14.5 s on two). A forked child inherits the built model without copying or
pickling it and returns only its result, so two lineages take the wall time of one.

Forking is used only where it is safe and wanted: on Linux, from a process that is not a
daemon (a Dask worker), with two cores or more available to it, and unless ``BCAD_SINGLE_CORE=1``
is set (as ``bcad batch`` sets it for its workers, which already keep every core busy).
Elsewhere the work runs in this process, when its result is first asked for: the same result,
later.
"""

from __future__ import annotations

import os
import pickle
import sys
import time
from collections.abc import Callable, Iterator
from contextlib import closing, suppress
from typing import Any

from bcad.worker_env import SINGLE_CORE_VARIABLE

#: a child that has not answered this long after it started (and SLOWER times as long as the
#: caller's estimate of the work's time) is stopped, and its work done in this process instead: a
#: wedged child never hangs a run (generous: a child slowed by a busy machine is not given up on)
PATIENCE_SECONDS = 60.0
SLOWER = 10.0


def can_fork() -> bool:
    """Whether :class:`Ahead` runs its work in a forked child (module docstring)."""
    if not sys.platform.startswith("linux"):
        return False
    import multiprocessing

    if multiprocessing.current_process().daemon:
        return False
    if os.environ.get(SINGLE_CORE_VARIABLE, "").strip() == "1":
        return False
    try:
        cores = len(os.sched_getaffinity(0))
    except (AttributeError, OSError):
        cores = os.cpu_count() or 1
    return min(cores, _cgroup_cores()) >= 2


def _cgroup_cores(path: str = "/sys/fs/cgroup/cpu.max") -> float:
    """The CPUs a container's quota allows this process (cgroup v2's "quota period"; unlimited
    where there is none or it cannot be read)."""
    try:
        with open(path, encoding="ascii") as limits:
            quota, period = limits.read().split()[:2]
        return float(quota) / float(period) if quota != "max" else float("inf")
    except (OSError, ValueError, ZeroDivisionError):
        return float("inf")


class Ahead:
    """``work(*args)`` started now in a forked child (where :func:`can_fork`), its value read by
    :meth:`result`; where the child fails, is stopped or forking is not available, the value is
    computed in this process instead, so :meth:`result` always returns what ``work`` returns
    here (which must therefore not depend on where it runs: its own random streams).
    :meth:`cancel` stops a child whose result is no longer wanted, as leaving a ``with`` block
    does."""

    def __enter__(self) -> Ahead:
        return self

    def __exit__(self, *exc_info) -> None:
        """Leaving a ``with`` block stops a child whose value was not read (an error, say)."""
        self.cancel()

    def __init__(self, work: Callable[..., Any], *args: Any, stream: bool = False):
        self.work, self.args, self.stream = work, args, stream
        self.started = time.perf_counter()
        self.process = None
        self.reader = None
        if can_fork():
            self._fork()

    def _fork(self) -> None:
        import multiprocessing

        context = multiprocessing.get_context("fork")
        reader, writer = context.Pipe(duplex=False)
        try:
            process = context.Process(
                target=_child, args=(reader, writer, os.getpid(), self.work, self.args, self.stream), daemon=True
            )
            process.start()
        except OSError:  # no memory or process slot for a child: this process does the work
            reader.close()
            writer.close()
            return
        writer.close()
        self.process, self.reader = process, reader

    def _messages(self, expected_seconds: float) -> Iterator[tuple[str, bytes]]:
        """The child's messages (status, payload) as they come, until it dies or sends none in
        time (SLOWER times ``expected_seconds``, and PATIENCE_SECONDS, from its start); the child
        is stopped after."""
        patience = max(PATIENCE_SECONDS, SLOWER * expected_seconds)
        try:
            while self.reader.poll(max(patience - (time.perf_counter() - self.started), 0.0) + 1.0):
                yield self.reader.recv()
        except (EOFError, OSError):
            pass  # the child died without (the rest of) its answer
        finally:
            self.cancel()

    def result(self, expected_seconds: float = 0.0) -> Any:
        """The work's value. ``expected_seconds``: about how long the work takes, as the caller
        measured on its own share (a child slower than SLOWER times that, and than
        PATIENCE_SECONDS, is given up on)."""
        if self.process is not None:
            with closing(self._messages(expected_seconds)) as messages:
                status, payload = next(messages, ("none", b""))
                if status == "ok":
                    with suppress(pickle.UnpicklingError):
                        return pickle.loads(payload)
        return self.work(*self.args)

    def items(self, expected_seconds: float = 0.0) -> Iterator[Any]:
        """Each value ``work`` (a generator function, ``stream=True``) yields, in order, as the
        child sends them: the first can be used while the child computes the next. Where the
        child fails, is too slow (:meth:`result`) or forking is not available, the rest are
        computed in this process (the generator run again, the values already received skipped)."""
        received = 0
        if self.process is not None:
            with closing(self._messages(expected_seconds)) as messages:
                for status, payload in messages:
                    if status != "item":
                        if status == "end":
                            return
                        break
                    try:
                        item = pickle.loads(payload)
                    except pickle.UnpicklingError:
                        break
                    received += 1
                    yield item
        for index, item in enumerate(self.work(*self.args)):
            if index >= received:
                yield item

    def cancel(self) -> None:
        """Stop the child, if any (its value will not be read): SIGTERM, then SIGKILL if it has
        not ended within a second."""
        if self.process is None:
            return
        self.reader.close()  # a child blocked sending its value sees the pipe broken
        if self.process.is_alive():
            self.process.terminate()
        self.process.join(1.0)
        if self.process.is_alive():
            self.process.kill()
            self.process.join()
        self.process = None


def _child(reader, writer, parent: int, work: Callable[..., Any], args: tuple, stream: bool = False) -> None:
    """The forked child: compute, send the pickled value (or a failure), exit; ``stream``: send
    each value the work yields as it comes, then an end. It keeps no end of the pipe but its own
    (a dead parent breaks it), takes the default actions on SIGTERM and SIGINT (a host program's
    handlers are not its), and dies with its parent."""
    import signal

    reader.close()
    signal.signal(signal.SIGTERM, signal.SIG_DFL)
    signal.signal(signal.SIGINT, signal.SIG_DFL)
    _die_with(parent)
    try:
        try:
            if stream:
                _stream(work(*args), writer)
                message = ("end", b"")
            else:
                message = ("ok", pickle.dumps(work(*args), protocol=pickle.HIGHEST_PROTOCOL))
        except BaseException as exc:  # the parent recomputes in its own process and reports there
            message = ("failed", repr(exc))
        writer.send(message)
    except OSError:
        pass  # the parent closed its end: the rest is no longer wanted
    finally:
        writer.close()


def _stream(items: Iterator[Any], writer) -> None:
    """Send each item as it comes, from a thread of its own: a pipe holds 64 KB, and a child that
    waited for its parent to read the first item (a screened pool of starts, 200 KB) would compute
    nothing more until the parent asked for it."""
    import queue
    import threading

    outbox: queue.Queue = queue.Queue()
    unwanted = threading.Event()

    def send() -> None:
        while (message := outbox.get()) is not None:
            try:
                writer.send(message)
            except OSError:  # the parent closed its end (it stopped this child): nothing more is wanted
                unwanted.set()
                return

    sender = threading.Thread(target=send, daemon=True)
    sender.start()
    try:
        for item in items:
            if unwanted.is_set():
                break
            outbox.put(("item", pickle.dumps(item, protocol=pickle.HIGHEST_PROTOCOL)))
    finally:
        outbox.put(None)
        sender.join()


def _die_with(parent: int) -> None:
    """Have Linux kill this process when its parent ends (prctl PR_SET_PDEATHSIG), and end now if
    the parent already has."""
    import ctypes
    import signal

    try:
        ctypes.CDLL(None, use_errno=True).prctl(1, int(signal.SIGKILL), 0, 0, 0)  # 1: PR_SET_PDEATHSIG
    except (OSError, AttributeError):
        pass
    if os.getppid() != parent:
        os._exit(1)
