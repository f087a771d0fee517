"""Shared helpers: writing problem files and running the CLI."""

from __future__ import annotations

import json
import os
import shutil
import subprocess
import sys
import textwrap
from collections.abc import Callable
from pathlib import Path

import pytest

# One BLAS thread per test process, set before any test module imports numpy (nothing above does): the suite runs a
# worker per core (pytest-xdist), and two workers each spinning a thread pool on two cores made
# numpy-heavy tests up to 25 times slower (bcad's own command and batch workers do the same:
# bcad.worker_env). A user's setting is kept.
for _name in ("OPENBLAS_NUM_THREADS", "OMP_NUM_THREADS", "MKL_NUM_THREADS"):
    os.environ.setdefault(_name, "1")

REPO = Path(__file__).resolve().parent.parent
RX90_URDF = REPO / "robots" / "rx90.urdf"
RX90_EXAMPLE = REPO / "problems" / "rx90_face_on_face.yaml"
DOCS = REPO / "docs"


#: the modules whose tests take longest (README and tutorial commands, whole solves of the
#: examples, certified bounds), heaviest first: pytest-xdist hands tests out in collection order, and
#: these, collected last, left one worker running them alone while the other had finished
HEAVIEST_FIRST = (
    "test_readme_commands.py",
    "test_plot.py",
    "test_docs.py",
    "test_directional.py",
    "test_configurations.py",
    "test_exact_climb.py",
    "test_global_search.py",
    "test_readme.py",
    "test_calibrate.py",
    "test_camera_calibration.py",
    "test_relations_end_to_end.py",
    "test_peg_in_hole.py",
    "test_maxerror_exact.py",
)


def pytest_collection_modifyitems(items) -> None:
    """The heaviest modules' tests first (:data:`HEAVIEST_FIRST`), the others in their order after
    them: the two workers then end together (a stable sort, the same on every worker)."""
    rank = {name: k for k, name in enumerate(HEAVIEST_FIRST)}
    items.sort(key=lambda item: rank.get(item.path.name, len(rank)))


def documentation() -> str:
    """What a user reads: the README and every page of the documentation, as one text."""
    pages = [REPO / "README.md", *sorted(DOCS.rglob("*.md"))]
    return "\n\n".join(page.read_text(encoding="utf-8") for page in pages)


# Q = X + L with L ~ N(0, 0.3^2); the closing link scores Q - 3 ~ N(0, 0.4^2);
# X has the prior N(1, 2^2). Then I(X) = N(X; 3, 0.5^2): a problem whose optimum
# and posterior are known in closed form. Tests append their own `solver:` line.
ONE_LINK_GRAPH = """
name: one-link
frames: [a, m, b]
links:
  - {name: unknown, parent: a, child: m, status: XFFFFF, bounds: {tx: [-10, 10]}, distributions: {tx: 'normal(1, 2)'}}
  - {name: free, parent: m, child: b, status: LFFFFF, distributions: {tx: 'normal(0, 0.3)'}}
  - {name: measured, parent: a, child: b, pose: [3, 0, 0, 0, 0, 0], status: LFFFFF, close: true, distributions: {tx: 'normal(0, 0.4)'}}
"""


@pytest.fixture
def forks(monkeypatch) -> list[bool]:
    """Whether each :class:`bcad.parallel.Ahead` made in the test started a child process."""
    from bcad import parallel

    started: list[bool] = []
    fork = parallel.Ahead._fork

    def counted(job) -> None:
        fork(job)
        started.append(job.process is not None)

    monkeypatch.setattr(parallel.Ahead, "_fork", counted)
    return started


@pytest.fixture
def write_problem(tmp_path):
    """Write a (dedented) YAML problem into the test's folder and return its path."""

    def write(text: str, name: str = "problem.yaml") -> Path:
        path = tmp_path / name
        path.write_text(textwrap.dedent(text).lstrip("\n"), encoding="utf-8")
        return path

    return write


def run_bcad(
    *args: str, cwd: Path | None = None, env_extra: dict[str, str] | None = None
) -> subprocess.CompletedProcess:
    """Run the real ``bcad`` entry point in a subprocess (exit code, stdout, stderr)."""
    import os

    return subprocess.run(
        [sys.executable, "-m", "bcad.cli", *map(str, args)],
        capture_output=True,
        text=True,
        cwd=cwd,
        env=None if env_extra is None else {**os.environ, **env_extra},
    )


def made_once(tmp_path_factory, name: str, make: Callable[[Path], None]) -> Path:
    """A folder where ``make(folder)`` has run once in this test run. The suite's workers
    (pytest-xdist) share it: the first to ask makes it while the others wait on a lock, so an
    expensive result that several modules read is computed once, not once per module and worker.
    A ``make`` that fails leaves nothing behind, and the next to ask runs it again."""
    root = tmp_path_factory.getbasetemp()
    if os.environ.get("PYTEST_XDIST_WORKER"):
        root = root.parent  # the run's folder, above each worker's own
    try:
        import fcntl
    except ImportError:  # no POSIX locks (Windows): each worker makes its own
        folder = tmp_path_factory.mktemp(name)
        make(folder)
        return folder
    folder = root / f"made-once-{name}"
    with open(root / f"made-once-{name}.lock", "w") as lock:
        fcntl.flock(lock, fcntl.LOCK_EX)  # released when the file closes
        if not (folder / ".made").exists():
            shutil.rmtree(folder, ignore_errors=True)
            folder.mkdir()
            make(folder)
            (folder / ".made").touch()
    return folder


def rx90_solved(tmp_path_factory, backend: str = "bayes") -> Path:
    """The RX90 example solved with 2e4 posterior samples (seed 0) by ``backend``, made once
    per test run (:func:`made_once`): the path of its JSON result, and beside it, samples.npz,
    what ``--samples-out`` wrote."""

    def make(folder: Path) -> None:
        run = run_bcad(
            "solve",
            RX90_EXAMPLE,
            "--backend",
            backend,
            "--samples",
            "2e4",
            "-o",
            folder / "result.json",
            "--samples-out",
            folder / "samples.npz",
            "--quiet",
        )
        assert run.returncode in ((0,) if backend == "bayes" else (0, 3)), run.stderr

    return made_once(tmp_path_factory, f"rx90-{backend}-2e4", make) / "result.json"


def quick_start_solved(tmp_path_factory) -> Path:
    """The README quick start's ``bcad solve problems/rx90_face_on_face.yaml``, run as written
    (from the repository, the default seed and samples) once per test run (:func:`made_once`):
    a folder with its stdout (the JSON result, ``result.json``), its stderr (``stderr.txt``) and
    its exit code (``returncode``). The tests that read the default RX90 solve share it."""

    def make(folder: Path) -> None:
        run = run_bcad("solve", "problems/rx90_face_on_face.yaml", cwd=REPO)
        (folder / "result.json").write_text(run.stdout, encoding="utf-8")
        (folder / "stderr.txt").write_text(run.stderr, encoding="utf-8")
        (folder / "returncode").write_text(str(run.returncode), encoding="utf-8")

    return made_once(tmp_path_factory, "rx90-quick-start", make)


def quick_start_result(tmp_path_factory) -> Path:
    """The path of the quick start's JSON result (:func:`quick_start_solved`), after checking
    that it exited 0 (its stderr in the failure's message)."""
    run = quick_start_solved(tmp_path_factory)
    assert (run / "returncode").read_text() == "0", (run / "stderr.txt").read_text(encoding="utf-8")[-3000:]
    return run / "result.json"


def document_made_once(tmp_path_factory, name: str, make: Callable[[], dict]) -> dict:
    """A JSON document ``make()`` returns, made once per test run (:func:`made_once`)."""

    def write(folder: Path) -> None:
        (folder / "document.json").write_text(json.dumps(make()))

    return json.loads((made_once(tmp_path_factory, name, write) / "document.json").read_text())


def assert_committed_calibration(fresh_file: Path, committed_file: Path) -> None:
    """A committed calibration result is what ``bcad calibrate`` writes now: the same parameters in
    the same order, each map within 1e-6 of its laplace_std and each laplace_std within 1e-6
    relative. (Exact to 1e-9 relative is more than the libraries keep: with numpy 2.4 and scipy
    1.17 a MAP moved by 6.7e-9 relative, 2e-8 of its standard deviation.)"""
    fresh = json.loads(Path(fresh_file).read_text())["parameters"]
    committed = json.loads(Path(committed_file).read_text())["parameters"]
    assert list(fresh) == list(committed)
    for name, entry in fresh.items():
        tolerance = 1e-6 * entry["laplace_std"] + 1e-12
        assert committed[name]["map"] == pytest.approx(entry["map"], rel=0, abs=tolerance), name
        assert committed[name]["laplace_std"] == pytest.approx(entry["laplace_std"], rel=1e-6), name
