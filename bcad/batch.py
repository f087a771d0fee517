"""Batch runs and design studies: ``bcad batch``.

Each problem runs with the command for its kind (``solve`` for Bayesian
problems, ``maxerror`` for clearance chains). ``--sweep KEY=V1,V2,...`` turns a
problem into a sweep; several ``--sweep`` make a grid. Results go to
``DIR/<stem>.json`` (``DIR/<stem>__<key>=<value>....json`` for a sweep
point), written atomically; ``DIR/summary.jsonl`` gets one line per problem.

Seeds are derived from ``--seed``, the problem's file name and the sweep
point only, never from the order or the worker, so local and distributed
runs give the same results. Tasks run in a local process pool, or on a
running Dask scheduler (``--scheduler``); either way the results are written
by this process as they arrive.
"""

from __future__ import annotations

import copy
import itertools
import json
import math
import os
import re
import signal
import threading
import time
import zlib
from collections.abc import Callable
from contextlib import contextmanager
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import yaml

from bcad.errors import InputError, quoted
from bcad.model.source import not_plain_data

SAFE = re.compile(r"[^A-Za-z0-9._=+-]")


class BatchUsageError(Exception):
    """A bad command line (exit code 2)."""


@dataclass(frozen=True)
class Sweep:
    key: str
    values: tuple[Any, ...]


@dataclass(frozen=True)
class Task:
    file: str  # absolute path of the problem file
    name: str  # the file's name, part of the seed
    stem: str  # the result's file name, without .json
    point: tuple[tuple[str, Any], ...]  # the sweep's assignments
    seed: int
    output: str
    timeout: float | None = None  # seconds; enforced where the task runs in a process's main thread
    confine: str | None = None  # the folder the task may read files from (bcad.model.source.confined)


#: a pool restarts after a worker dies; a task that was running then runs at most this often
POOL_ATTEMPTS = 3
#: how often a pool worker checks that its parent lives (seconds)
PARENT_POLL_SECONDS = 1.0
#: seconds allowed to connect to a Dask scheduler
SCHEDULER_TIMEOUT = 10
SCHEDULER_ADDRESS = re.compile(r"(tcp|tls)://[A-Za-z0-9.\-\[\]:]+:\d{1,5}")


class TaskTimeout(Exception):
    """A task ran past ``--timeout``."""


@contextmanager
def time_limit(seconds: float | None):
    """Raise :class:`TaskTimeout` in the block after ``seconds`` (a SIGALRM timer).

    Only in a process's main thread (the local pool's workers, ``--jobs 1``):
    signals cannot interrupt other threads, such as a Dask worker's.
    """
    if not seconds or threading.current_thread() is not threading.main_thread() or not hasattr(signal, "setitimer"):
        yield
        return

    def expire(signum, frame):
        raise TaskTimeout(f"ran past --timeout {seconds:g} s")

    previous = signal.signal(signal.SIGALRM, expire)
    signal.setitimer(signal.ITIMER_REAL, seconds)
    try:
        yield
    finally:
        signal.setitimer(signal.ITIMER_REAL, 0)
        signal.signal(signal.SIGALRM, previous)


def parse_sweep(text: str) -> Sweep:
    key, equals, values = text.partition("=")
    key = key.strip()
    if not equals or not key or not values.strip():
        raise BatchUsageError(f"--sweep '{text}' is not KEY=V1,V2,...")
    parsed = []
    for value in values.split(","):
        try:
            item = yaml.safe_load(value.strip())
        except (yaml.YAMLError, ValueError):  # ValueError: an integer of more digits than Python converts
            raise BatchUsageError(f"--sweep {quoted(text, 60)}: cannot read the value {quoted(value, 40)}") from None
        if isinstance(item, str):
            # YAML 1.1 reads 1e-4 (no dot) as text; a user means the number.
            try:
                number = float(item)
            except ValueError:
                pass
            else:
                if not math.isfinite(number):
                    raise BatchUsageError(f"--sweep '{text}': the value '{value}' is not a finite number")
                item = number
        elif isinstance(item, float) and not math.isfinite(item):
            raise BatchUsageError(f"--sweep '{text}': the value '{value}' is not a finite number")
        problem = not_plain_data(item, MAX_SET_DEPTH, MAX_SET_ITEMS)
        if problem:
            raise BatchUsageError(
                f"--sweep '{text}': the value '{value}' {problem}; expected a number, a word, "
                "true/false, or a [list] of them"
            )
        parsed.append(item)
    if any(not segment.strip() for segment in key.split(".")):
        raise BatchUsageError(
            f"--sweep '{text}': the key '{key}' has an empty segment; expected KEY.KEY... such as "
            "links.free.distributions.tx.std"
        )
    return Sweep(key, tuple(parsed))


#: the runs of one batch, at most: problems times the --sweep grid's points
MAX_TASKS = 10_000
#: how deep and how large a --sweep value may be (a list of lists ...)
MAX_SET_DEPTH, MAX_SET_ITEMS = 8, 10_000


def task_seed(seed: int, name: str, point: tuple[tuple[str, Any], ...]) -> int:
    """A seed from --seed, the file name and the sweep point only (order and worker free)."""
    text = json.dumps([seed, name, [[key, value] for key, value in point]], sort_keys=True, default=str)
    return zlib.crc32(text.encode()) & 0x7FFFFFFF


def _label(value: Any) -> str:
    return SAFE.sub("_", str(value))


#: the longest result file stem (file systems allow 255 bytes for a name)
MAX_STEM = 200


def short_stem(stem: str) -> str:
    """``stem``, or, past MAX_STEM, its start and a hash of the whole (distinct points, distinct files)."""
    import hashlib

    if len(stem.encode("utf-8")) <= MAX_STEM:
        return stem
    head = stem.encode("utf-8")[: MAX_STEM - 20].decode("utf-8", "ignore")
    return f"{head}__{hashlib.sha256(stem.encode('utf-8', 'surrogatepass')).hexdigest()[:12]}"


def _check_keys(files: list[Path], sweeps: list[Sweep]) -> None:
    """Every --sweep key reaches into every problem file that reads (a file that does not read
    is that task's error, reported in its result), and each of its values, set alone in a file the
    schema takes, passes the schema there: a key that does not reach, or a value the schema
    refuses, is a usage error, said before anything runs and named as the command line's (a file
    the schema refuses as it is reports that in its runs' results)."""
    from bcad.model.clearance import problem_or_chain_from_document
    from bcad.model.source import load_yaml

    if not sweeps:
        return
    first = tuple((sweep.key, sweep.values[0]) for sweep in sweeps)
    for file in files:
        try:
            doc = load_yaml(file)
        except InputError:
            continue
        try:
            apply_sweep(doc.data, first)
        except InputError as exc:
            raise BatchUsageError(f"{file}: {exc.message}") from None
        data = doc.data
        try:
            problem_or_chain_from_document(doc)
        except InputError:
            continue  # the file itself: each of its runs reports it
        for sweep in sweeps:
            for value in sweep.values:
                doc.data = apply_sweep(data, ((sweep.key, value),))
                try:
                    problem_or_chain_from_document(doc)
                except InputError as exc:
                    raise BatchUsageError(
                        f"--sweep {sweep.key}={value}: {file.name} does not take it: {exc.message}"
                    ) from None
        doc.data = data


def plan_tasks(
    files: list[Path], out: Path, seed: int, sweeps: list[Sweep], timeout: float | None = None
) -> list[Task]:
    """Every (file, sweep point) pair, with its seed and result path. The grid's size is checked
    first: each sweep's values are then checked against every file (:func:`_check_keys`), at most
    MAX_TASKS schema checks."""
    count = len(files) * math.prod(len(sweep.values) for sweep in sweeps)
    if count > MAX_TASKS:
        raise BatchUsageError(
            f"{len(files)} problem(s) and the --sweep grid make {count:,} runs; a batch runs at most "
            f"{MAX_TASKS:,} (split it into several batches with --out folders of their own)"
        )
    _check_keys(files, sweeps)
    short = [sweep.key.rsplit(".", 1)[-1] for sweep in sweeps]
    names = [s if short.count(s) == 1 else sweep.key for s, sweep in zip(short, sweeps)]
    points = list(itertools.product(*[sweep.values for sweep in sweeps])) if sweeps else [()]
    from bcad.model.source import confinement

    root = confinement()  # carried by each task: a Dask worker elsewhere has no environment of ours
    tasks, seen = [], {}
    for file in files:
        for values in points:
            point = tuple((sweep.key, value) for sweep, value in zip(sweeps, values))
            stem = short_stem(
                file.stem + "".join(f"__{_label(name)}={_label(value)}" for name, value in zip(names, values))
            )
            if stem in seen:
                raise BatchUsageError(
                    f"{file} and {seen[stem]} would both write {stem}.json; give them different names"
                )
            seen[stem] = file
            tasks.append(
                Task(
                    str(file.resolve()),
                    file.name,
                    stem,
                    point,
                    task_seed(seed, file.name, point),
                    str(out / f"{stem}.json"),
                    timeout,
                    None if root is None else str(root),
                )
            )
    # A result or the summary must never replace a problem file (a problem written as JSON).
    inputs = {os.path.realpath(file) for file in files}
    for written in [task.output for task in tasks] + [str(out / "summary.jsonl")]:
        if os.path.realpath(written) in inputs:
            raise BatchUsageError(f"{written} is one of the input files; choose another --out")
    return tasks


def _opened(node: Any, parent: Any, slot: Any) -> Any:
    """``node``, with a distribution shorthand replaced (in its parent) by its mapping form."""
    from bcad.model.distributions import parse_shorthand

    if isinstance(node, str) and parent is not None:
        try:
            mapping = parse_shorthand(node)
        except ValueError:
            return node
        parent[slot] = mapping
        return mapping
    return node


def _slot(node: Any, segment: str) -> Any:
    """The key, position or ``name`` that ``segment`` designates in a mapping or list."""
    if isinstance(node, dict) and segment in node:
        return segment
    if isinstance(node, list):
        if segment.lstrip("-").isdigit() and -len(node) <= int(segment) < len(node):
            return int(segment)
        for index, item in enumerate(node):
            if isinstance(item, dict) and item.get("name") == segment:
                return index
    raise KeyError(segment)


#: top-level mappings of settings that --sweep may add to a file that lacks them
SETTINGS_SECTIONS = ("solver", "units")


def apply_sweep(data: Any, point: tuple[tuple[str, Any], ...]) -> Any:
    """A copy of the problem's data with each dotted KEY set to its value.

    Segments index mappings by key and lists by position or by an element's
    ``name``; a distribution shorthand is opened into its fields, so
    ``robots.arm1.joints.default.zero.std`` reaches the std of
    ``zero: normal(0, 0.05)``. The last segment may be a key new to an existing
    mapping (``solver.search_starts`` where the file's ``solver:`` lacks it), and a
    settings section (SETTINGS_SECTIONS) may be missing: the schema then checks
    them like any key of the file. Any other missing segment is an error.
    """
    data = copy.deepcopy(data)
    for key, value in point:
        segments = key.split(".")
        parent, parent_slot, node = None, None, data
        for depth, segment in enumerate(segments):
            node = _opened(node, parent, parent_slot)
            try:
                slot = _slot(node, segment)
            except KeyError:
                if depth == len(segments) - 1 and isinstance(node, dict):
                    slot = segment  # a new last key in an existing mapping: the schema checks it
                elif depth == 0 and segment in SETTINGS_SECTIONS and isinstance(node, dict):
                    node[segment] = {}  # solver.search_starts in a file without solver:
                    slot = segment
                else:
                    where = ".".join(segments[:depth]) or "the top level"
                    raise InputError(
                        "<--sweep>", f"--sweep {key}: '{segment}' is not in {where} of this problem"
                    ) from None
            if depth == len(segments) - 1:
                node[slot] = value
            else:
                parent, parent_slot, node = node, slot, node[slot]
    return data


def _key_figures(document: dict, with_seed: bool = False) -> dict:
    """The figures a summary line keeps from a result, read through its family's typed model: its
    status (``warning`` where the result cannot be trusted, else ``ok``), log p(X) I(X) and the
    scored parameters' Table 2 std and weighted std, or maxerror's maxima and bounds; with ``with_seed``, a
    design result's seed."""
    from bcad.bayes.result import DesignResult
    from bcad.result import result_model

    result = result_model(document["kind"]).model_validate(document)
    status = "warning" if result.warnings else "ok"
    if isinstance(result, DesignResult):
        links = {
            name: {p: link.std[link.params.index(p)] for p in link.constrained}
            for name, link in result.posterior.links.items()
        }
        # the posterior's (weighted by the scores): how closely the scores hold each parameter,
        # beside Table 2's plain std, the spread the uncertain parameters alone give it
        weighted = {
            name: {p: link.weighted.std[link.params.index(p)] for p in link.constrained}
            for name, link in result.posterior.links.items()
            if link.weighted is not None and link.weighted.std is not None
        }
        figures = {
            "status": status,
            "kind": "solve",
            "log_objective": result.objective.log_value,
            "log_objective_se": result.objective.log_value_se,
            "constrained_std": links,
            "constrained_weighted_std": weighted,
        }
        figures["warnings"] = [warning.code for warning in result.warnings]
        if with_seed:
            figures["seed"] = result.seed
        return figures
    return {
        "status": status,
        "kind": "maxerror",
        "units": {"length": result.units.length, "angle": result.units.angle},
        "rotation": {"max": result.rotation.max, "upper_bound": result.rotation.upper_bound},
        "translation": {"max": result.translation.max, "upper_bound": result.translation.upper_bound},
    }


#: the summary key that carries a task's input files from the worker to the batch process
INPUTS_KEY = "_inputs"


def run_task(task: Task) -> tuple[dict, dict]:
    """Run one problem; never raises. Returns (result document, summary line)."""
    from bcad.runtime import tune_allocator

    tune_allocator()  # in a pool or Dask worker as in the bcad command (idempotent)
    start = time.perf_counter()
    summary = _summary_base(task)
    from bcad.io import recording_inputs

    inputs: dict = {}
    try:
        from bcad.model.source import confined

        with time_limit(task.timeout), recording_inputs() as inputs, confined(task.confine):
            document = _run_problem(task)
        # A result that cannot be trusted (bcad.bayes.trust) is kept, with status "warning".
        summary.update(_key_figures(document))
    except Exception as exc:  # every failure becomes a result, so the batch goes on
        from bcad.bayes.genetic import SolverError

        kind = (
            "invalid_input"
            if isinstance(exc, InputError)
            else "solver_error"
            if isinstance(exc, SolverError)
            else "timeout"
            if isinstance(exc, TaskTimeout)
            else "internal_error"
        )
        message = f"{type(exc).__name__}: {exc}" if kind == "internal_error" else str(exc)
        document = {"file": task.name, "point": dict(task.point), "error": {"type": kind, "message": message}}
        summary.update(status="error", error=document["error"])
    summary["seconds"] = round(time.perf_counter() - start, 3)
    # The files the task read, for the batch process that writes its result (record in
    # run_batch) to refuse replacing any of them; taken off the summary before it is written.
    summary[INPUTS_KEY] = sorted(str(path) for path in set(inputs.values()))
    return document, summary


def task_document(task: Task):
    """The task's problem file, read, with its sweep point applied (raises InputError)."""
    from bcad.model.source import load_yaml

    doc = load_yaml(task.file)
    try:
        doc.data = apply_sweep(doc.data, task.point)
    except InputError as exc:
        raise InputError(task.file, exc.message) from None
    return doc


def _run_problem(task: Task) -> dict:
    """The result document of one problem (raises on failure)."""
    from bcad.model.clearance import chain_problem_from_document, is_clearance_problem
    from bcad.model.problem import problem_from_document

    doc = task_document(task)
    if is_clearance_problem(doc.data):
        from bcad.worstcase.run import maxerror_document

        return maxerror_document(chain_problem_from_document(doc), tol=1e-6, model="first-order")
    from bcad.bayes.run import solve_document as solve
    from bcad.compiler import compile_problem

    return solve(compile_problem(problem_from_document(doc)), backend="bayes", seed=task.seed)


def _summary_base(task: Task) -> dict[str, Any]:
    """The fields every summary line starts with."""
    return {"file": task.name, "point": dict(task.point), "output": Path(task.output).name, "seed": task.seed}


def completed_result(path: Path) -> dict | None:
    """The summary figures of a finished, successful result at ``path`` (:func:`_key_figures`,
    with the result's ``seed`` where it has one), or None."""
    try:
        document = json.loads(path.read_text(encoding="utf-8"))
    except (OSError, ValueError, RecursionError):
        return None
    if not (isinstance(document, dict) and "error" not in document and "problem" in document):
        return None
    try:
        return _key_figures(document, with_seed=True)
    except (KeyError, TypeError, IndexError, ValueError, AttributeError):
        return None  # half a result, or another program's file: recompute it


@dataclass
class BatchOutcome:
    summaries: list[dict] = field(default_factory=list)

    @property
    def failed(self) -> int:
        return sum(line["status"] == "error" for line in self.summaries)

    @property
    def warned(self) -> int:
        """Results that carry warnings: computed now, or kept by --resume."""
        return sum(
            line["status"] == "warning" or (line["status"] == "skipped" and line.get("result_status") == "warning")
            for line in self.summaries
        )


#: an earlier summary larger than this is not read for --resume's seconds (a million lines)
EARLIER_SUMMARY_BYTES = 1 << 28


def _earlier_seconds(out: Path) -> dict[str, float]:
    """Each result's seconds in the summary an earlier run left in ``out`` (none where there is no
    readable one): what --resume keeps beside the result it skips."""
    path = out / "summary.jsonl"
    try:
        if not path.is_file() or path.stat().st_size > EARLIER_SUMMARY_BYTES:
            return {}
        text = path.read_text(encoding="utf-8")
    except (OSError, ValueError):
        return {}
    seconds = {}
    for row in text.splitlines():
        try:
            line = json.loads(row, parse_int=float)  # (an integer of 400 digits: inf, not an OverflowError)
        except (ValueError, RecursionError):
            continue
        if not isinstance(line, dict) or not isinstance(line.get("output"), str):
            continue
        value = line.get("seconds")  # (a skipped line carries its result's own, where it was known)
        if isinstance(value, float) and math.isfinite(value) and value >= 0.0:
            seconds[line["output"]] = value
    return seconds


def run_batch(
    tasks: list[Task],
    *,
    jobs: int,
    scheduler: str | None = None,
    resume: bool = False,
    on_done: Callable[[dict], None] | None = None,
) -> BatchOutcome:
    """Run the tasks, write each result as it arrives, and the summary at the end."""
    from bcad.io import write_json_atomic

    summaries: dict[int, dict] = {}
    pending: list[int] = []
    if tasks:
        from bcad.io import remove_stale_temporaries

        remove_stale_temporaries(
            Path(tasks[0].output).parent, [Path(task.output).name for task in tasks] + ["summary.jsonl"]
        )
    earlier = _earlier_seconds(Path(tasks[0].output).parent) if resume and tasks else {}
    for index, task in enumerate(tasks):
        existing = completed_result(Path(task.output)) if resume else None
        if existing is not None:
            # The seed is the result's own: --resume with another --seed keeps what was computed; the
            # result's status and the seconds it took (where the earlier summary has them) are kept.
            line = {
                **_summary_base(task),
                **existing,
                "status": "skipped",
                "result_status": existing["status"],
                "seconds": earlier.get(Path(task.output).name),
            }
            summaries[index] = line
            if on_done:
                on_done(line)
        else:
            pending.append(index)

    def record(index: int, document: dict, line: dict) -> None:
        read = [Path(name) for name in line.pop(INPUTS_KEY, [])]
        try:
            write_json_atomic(document, Path(tasks[index].output), read)
        except InputError as exc:  # the result path reaches one of the task's inputs: keep the input
            error = {"type": "invalid_input", "message": str(exc)}
            line = {
                **_summary_base(tasks[index]),
                "status": "error",
                "error": error,
                "seconds": line.get("seconds", 0.0),
            }
        summaries[index] = line
        if on_done:
            on_done(line)

    if pending:
        if scheduler:
            _run_on_dask(tasks, pending, scheduler, record)
        elif jobs == 1:
            for index in pending:
                record(index, *run_task(tasks[index]))
        else:
            _run_on_pool(tasks, pending, jobs, record)

    ordered = [summaries[index] for index in range(len(tasks))]
    out = Path(tasks[0].output).parent if tasks else None
    if out is not None:
        from bcad.io import write_text_atomic

        write_text_atomic("".join(json.dumps(line, sort_keys=True) + "\n" for line in ordered), out / "summary.jsonl")
    return BatchOutcome(ordered)


def _watch_parent(parent: int) -> None:
    """In a pool worker: exit when the batch process that started it is gone (killed with -9,
    say), instead of living on as an orphan."""

    def watch() -> None:
        while os.getppid() == parent:
            time.sleep(PARENT_POLL_SECONDS)
        os._exit(1)

    threading.Thread(target=watch, daemon=True, name="bcad-parent-watch").start()


def _run_on_pool(tasks: list[Task], pending: list[int], jobs: int, record, work=None) -> None:
    """Run on a pool of spawned workers; when a worker dies (killed, out of memory) the pool is
    restarted and the tasks it had not finished run again, each at most POOL_ATTEMPTS times.
    ``work`` replaces :func:`run_task` (tests)."""
    import multiprocessing
    from concurrent.futures import ProcessPoolExecutor, as_completed
    from concurrent.futures.process import BrokenProcessPool

    from bcad.worker_env import single_threaded_environment

    context = multiprocessing.get_context("spawn")
    attempts: dict[int, int] = {}
    remaining = list(pending)
    while remaining:
        retry: list[int] = []
        # Workers inherit the environment when they start, before anything imports numpy
        # in them (a spawned worker re-imports the parent's main module first).
        with (
            single_threaded_environment(),
            ProcessPoolExecutor(
                max_workers=jobs, mp_context=context, initializer=_watch_parent, initargs=(os.getpid(),)
            ) as pool,
        ):
            futures = {pool.submit(work or run_task, tasks[index]): index for index in remaining}
            for future in as_completed(futures):
                index = futures[future]
                try:
                    document, line = future.result()
                except BrokenProcessPool as exc:  # a worker died: this task may be innocent
                    attempts[index] = attempts.get(index, 0) + 1
                    if attempts[index] < POOL_ATTEMPTS:
                        retry.append(index)
                        continue
                    document, line = _lost(tasks[index], exc)
                except Exception as exc:
                    document, line = _lost(tasks[index], exc)
                record(index, document, line)
        remaining = sorted(retry)


def check_scheduler_address(scheduler: str) -> None:
    """A Dask scheduler address bcad can reach: tcp://HOST:PORT or tls://HOST:PORT."""
    if not SCHEDULER_ADDRESS.fullmatch(scheduler):
        raise BatchUsageError(
            f"--scheduler {scheduler!r} is not an address such as tcp://HOST:8786 (tcp:// or tls://, a host and a port)"
        )


def _connect(Client, scheduler: str):
    """A Dask client, or :class:`BatchUsageError` within SCHEDULER_TIMEOUT seconds.

    Dask's own timeout does not cover a server that accepts the connection and
    never answers, so the client is made in a daemon thread that is abandoned
    when it takes too long.
    """
    outcome: dict[str, object] = {}

    def connect() -> None:
        try:
            outcome["client"] = Client(scheduler, timeout=f"{SCHEDULER_TIMEOUT}s")
        except BaseException as exc:  # refused, timed out, not a Dask scheduler, TLS without certificates...
            outcome["error"] = exc

    thread = threading.Thread(target=connect, daemon=True, name="bcad-dask-connect")
    thread.start()
    thread.join(SCHEDULER_TIMEOUT + 2)
    if "client" in outcome:
        return outcome["client"]
    if "error" in outcome:
        exc = outcome["error"]
        if isinstance(exc, (OSError, TimeoutError)):
            raise BatchUsageError(f"cannot reach the Dask scheduler at {scheduler}: {type(exc).__name__}: {exc}")
        # something answered, but not as a Dask scheduler (its bytes read as a message give nonsense
        # such as a MemoryError), or the address needs what is not given (tls:// without certificates)
        raise BatchUsageError(
            f"no Dask scheduler answers at {scheduler} (what answered is not one, or the address needs a "
            f"setting not given, such as tls:// certificates: {type(exc).__name__}: {quoted(str(exc), 120)})"
        )
    raise BatchUsageError(f"the Dask scheduler at {scheduler} did not answer within {SCHEDULER_TIMEOUT} s")


#: what a --scheduler run without the dask extra is told
NO_DASK = "--scheduler needs dask.distributed: pip install -e '.[dask]'"


def require_dask() -> None:
    """A :class:`BatchUsageError` where dask.distributed cannot be imported (before any run starts:
    no progress bar is drawn for a run that cannot start; the run imports it anyway)."""
    try:
        import dask.distributed  # noqa: F401
    except ImportError:
        raise BatchUsageError(NO_DASK) from None


def _run_on_dask(tasks: list[Task], pending: list[int], scheduler: str, record) -> None:
    check_scheduler_address(scheduler)
    try:
        from dask.distributed import Client, as_completed
    except ImportError:
        raise BatchUsageError(NO_DASK) from None
    client = _connect(Client, scheduler)
    try:
        futures = {
            client.submit(run_task, tasks[index], pure=False, key=f"bcad-{tasks[index].stem}-{index}"): index
            for index in pending
        }
        for future in as_completed(list(futures)):
            index = futures[future]
            try:
                document, line = future.result()
            except Exception as exc:
                document, line = _lost(tasks[index], exc)
            record(index, document, line)
    finally:
        client.close()


def _lost(task: Task, exc: Exception) -> tuple[dict, dict]:
    error = {"type": "internal_error", "message": f"the worker failed: {type(exc).__name__}: {exc}"}
    document = {"file": task.name, "point": dict(task.point), "error": error}
    line = {**_summary_base(task), "status": "error", "error": error, "seconds": 0.0}
    return document, line
