"""The ``bcad`` command line.

Exit codes: 0 success, 1 internal error, 2 invalid input or command line,
3 a result that was written with warnings (it cannot be trusted as it is).
Results go to stdout (or a file); messages and progress go to stderr.
"""

from __future__ import annotations

import os

from bcad.worker_env import THREAD_VARIABLES

# One BLAS thread unless the user asks for more: bcad's hot loops are many small
# (3 x 3) @ (3 x N) products, where OpenBLAS's thread pool on a 2-core machine
# made `bcad solve` on the RX90 example take 7-11 s instead of 4-6 s.
# Set before anything imports numpy (typer and rich do not).
for _variable in THREAD_VARIABLES:
    os.environ.setdefault(_variable, "1")
# No pydantic plugins in the command line's process unless the user names some: they observe
# validation in services, and finding them reads every installed package's entry points at the
# first schema bcad builds (40-65 ms of each command's start on a 2-core machine).
os.environ.setdefault("PYDANTIC_DISABLE_PLUGINS", "__all__")

import errno  # noqa: E402
import functools  # noqa: E402
import json  # noqa: E402
import math  # noqa: E402
import sys  # noqa: E402
from collections.abc import Callable  # noqa: E402
from pathlib import Path  # noqa: E402

import typer  # noqa: E402

from bcad.errors import InputError, listed, printable, quoted  # noqa: E402
from bcad.version import __version__  # noqa: E402

app = typer.Typer(
    add_completion=False,
    rich_markup_mode=None,
    pretty_exceptions_enable=False,
    no_args_is_help=True,
    help="bcad: Bayesian robotic CAD. Problems are YAML files; docs/guide/language.md describes the language.\n\n"
    "Exit codes: 0 success; 2 invalid input or command line (FILE:LINE:COL: what is wrong); 3 a result written "
    "that cannot be trusted (its warnings, on stderr); 1 an internal error (BCAD_DEBUG=1 shows the traceback) "
    "or, for batch, a problem that failed.",
)


@functools.cache
def _console(to_stderr: bool):
    """The rich console of stdout or stderr. User text (names, messages, paths) is printed
    literally: no markup, no emoji codes, no highlighting. Made at the first message: rich's
    import is a quarter of ``bcad --help``'s time, which prints none."""
    from rich.console import Console

    return Console(stderr=to_stderr, markup=False, emoji=False, highlight=False)


def _plain(text: str):
    """``text`` as a rich text printed literally, the characters a terminal acts on as their
    escapes (:func:`bcad.errors.printable`): a name from a file or an argument never drives the
    terminal."""
    from rich.text import Text

    return Text(printable(text))


EXIT_INPUT = 2
EXIT_INTERNAL = 1
EXIT_UNTRUSTED = 3  # a result was written, but its warnings say it cannot be trusted


def _guarded(command: Callable) -> Callable:
    """Turn bcad's errors into a one-line message and an exit code, never a traceback."""

    @functools.wraps(command)
    def wrapper(*args, **kwargs):
        from bcad.io import recording_inputs

        try:
            try:
                # Every file the command reads is recorded: none of its outputs may replace one.
                with recording_inputs():
                    return command(*args, **kwargs)
            finally:
                sys.stdout.flush()  # here, so that a full device is reported (below), not at exit
        except InputError as exc:
            _console(True).print(_plain(str(exc)), soft_wrap=True)
            raise typer.Exit(EXIT_INPUT) from None
        except OSError as exc:
            if exc.errno not in OUTPUT_ERRORS:
                raise _internal(exc) from None
            _output_failed(exc)
        except (typer.Exit, typer.Abort, typer.TyperException, KeyboardInterrupt):
            raise  # typer's own: usage errors exit 2 with its message
        except Exception as exc:  # a bug in bcad, not in the input
            raise _internal(exc) from None

    return wrapper


def _internal(exc: Exception) -> typer.Exit:
    """Report a bug in bcad (not in the input) in one line; its exit."""
    if os.environ.get("BCAD_DEBUG"):
        raise exc
    from rich.text import Text

    _console(True).print(
        Text.assemble(
            ("internal error", "red"),
            printable(f": {type(exc).__name__}: {exc} (set BCAD_DEBUG=1 for the traceback, and please report it)"),
        ),
        soft_wrap=True,
    )
    return typer.Exit(EXIT_INTERNAL)


#: errors of writing the output (stdout to a full device, a closed pipe): the environment's, exit 2
OUTPUT_ERRORS = {errno.ENOSPC, errno.EPIPE, errno.EDQUOT, errno.EFBIG, errno.EIO}


def _report_output_failure(exc: OSError) -> None:
    """stdout could not be written: say so (not for a closed pipe, whose reader is gone);
    what remains buffered goes to the null device, so the exit is not a second error."""
    try:
        os.dup2(os.open(os.devnull, os.O_WRONLY), sys.stdout.fileno())
    except (OSError, ValueError, AttributeError):
        pass
    if exc.errno != errno.EPIPE:
        _console(True).print(_plain(f"cannot write the output: {exc.strerror or exc}"), soft_wrap=True)


def _output_failed(exc: OSError) -> None:
    """In a command: report that stdout could not be written, and exit 2."""
    _report_output_failure(exc)
    raise typer.Exit(EXIT_INPUT)


def _compile(path: Path, calibration: list[Path] | None = None):
    """The compiled problem, with ``--calibration`` results added to its ``calibration:``."""
    from bcad.arguments import COMMAND_LINE
    from bcad.compiler.problem import compile_with_calibrations

    return compile_with_calibrations(path, list(calibration or []), COMMAND_LINE)


def _calibration_note(compiled) -> None:
    """Information (exit 0): the calibration results' parameters this problem does not have as L."""
    for name, missing in compiled.calibration.not_applied.items():
        if missing:
            shown = listed(missing)
            _console(True).print(
                _plain(
                    f"note: {name} names {len(missing)} parameter(s) that are not L in this problem, "
                    f"left as the problem has them: {shown}"
                ),
                soft_wrap=True,
            )


CALIBRATION_HELP = (
    "a bcad calibrate result (JSON) whose posterior replaces the distributions of the L it names (repeatable)"
)


@app.command()
@_guarded
def validate(
    file: Path = typer.Argument(..., help="problem file (YAML)"),
    as_json: bool = typer.Option(False, "--json", metavar=" ", help="print the statistics as JSON"),
) -> None:
    """Validate a problem and print its statistics (Table 1 of the 2000 paper). A problem with
    measurements is checked as calibrate reads it: its CSV files, frames and rows, and its
    cameras' camera_info files; one without, for the posterior samples its solver asks for, and a
    note says what solve or posterior would refuse in it (no cycle, no X). A clearance problem's
    chain is built as maxerror builds it."""
    from bcad.model.source import load_yaml

    document = load_yaml(file)
    if isinstance(document.data, dict) and "chain" in document.data:
        # a clearance problem (bcad.model.clearance.is_clearance_problem: not imported for the others)
        _validate_chain(document, file, as_json)
        return
    from bcad.compiler import compile_problem
    from bcad.model.problem import problem_from_document

    compiled = compile_problem(problem_from_document(document))
    if compiled.problem.measurements:
        # what calibrate reads before it calibrates: the measurements' files, frames and rows, and
        # the cameras' files, checked by the same code (only where there are measurements to read)
        from bcad.calibration.model import CalibrationModel

        CalibrationModel(compiled)
    else:
        # the samples the file asks of solve and posterior, refused by them past their limit:
        # refused here too, at the same place (a default the file does not write is no error of it:
        # --samples sets another)
        from bcad.bayes.work import check_posterior_work, check_search_work

        if "posterior_samples" in compiled.problem.solver.model_fields_set:
            check_posterior_work(compiled, compiled.problem.solver.posterior_samples, None)
        check_search_work(compiled, compiled.problem.solver)
    if not compiled.problem.measurements:
        _refusal_note(compiled)
    if as_json:
        _write_json({"stats": compiled.stats.as_dict()}, None, file)
        return
    from bcad.report import stats_table

    _console(False).print(stats_table(compiled))


def _refusal_note(compiled) -> None:
    """Information (exit 0): what solve (and posterior) would refuse in a problem that validate
    accepts as a problem (a graph with no cycle describes a cell, but there is nothing to solve)."""
    from bcad.bayes.solvable import check_solvable

    for needs_unknowns, who in ((False, "bcad solve and bcad posterior refuse"), (True, "bcad solve refuses")):
        try:
            check_solvable(compiled, needs_unknowns=needs_unknowns)
        except InputError as error:
            _console(True).print(_plain(f"note: {who} this problem: {error.message}"), soft_wrap=True)
            return


def _validate_chain(document, file: Path, as_json: bool) -> None:
    """validate on a clearance problem: its schema, then its chain's joints and clearances as
    maxerror reads them (a URDF's joints, their axes), and their count."""
    from bcad.model.clearance import chain_problem_from_document
    from bcad.worstcase.error_map import build_error_map

    problem = chain_problem_from_document(document)
    error_map = build_error_map(problem)
    stats = {"joints": error_map.joints, "clearances": int((error_map.clearance > 0).sum())}
    if as_json:
        _write_json({"stats": stats}, None, file)
        return
    from bcad.report import chain_stats_table

    _console(False).print(chain_stats_table(problem.name, stats))


@app.command()
@_guarded
def graph(
    file: Path = typer.Argument(..., help="problem file (YAML)"),
    dot: bool = typer.Option(False, "--dot", metavar=" ", help="write Graphviz DOT instead of a tree"),
) -> None:
    """Show the spanning tree and the cycles with their closing links."""
    compiled = _compile(file)
    from bcad.report import graph_dot, graph_tree

    if dot:
        sys.stdout.write(graph_dot(compiled))
    else:
        _console(False).print(graph_tree(compiled))


def _sample_count(text: str, option: str) -> int:
    """Sample counts accept scientific notation: 1e5, 2.5e6 (:func:`bcad.arguments.sample_count`)."""
    from bcad.arguments import COMMAND_LINE, sample_count

    return sample_count(text, option.removeprefix("--"), COMMAND_LINE)


def _write_json(document: dict, output: Path | None, protected: Path | list[Path]) -> None:
    """Write JSON to a file atomically (temporary file, then rename), or to stdout."""
    from bcad.io import json_text, write_json_atomic

    if output is None:
        sys.stdout.write(json_text(document))
    else:
        write_json_atomic(document, output, protected)


class _GeneticProgress:
    """A solve's progress on stderr: the search (the GA's phase, temperature, samples and best log
    objective), then the posterior's samples at the solution."""

    def __init__(self, quiet: bool):
        from rich.progress import Progress, SpinnerColumn, TextColumn, TimeElapsedColumn

        # only on a terminal: where stderr is a file or a pipe, a progress display leaves nothing
        # but a stray blank line before the messages
        self.progress = (
            None
            if quiet or not _console(True).is_terminal
            else Progress(
                SpinnerColumn(),
                TextColumn("{task.description}", markup=False),
                TimeElapsedColumn(),
                console=_console(True),
                transient=True,
            )
        )
        self.task = None

    def __enter__(self):
        if self.progress:
            self.progress.__enter__()
            self.task = self.progress.add_task("solving", total=None)
        return self

    def __exit__(self, *exc):
        if self.progress:
            self.progress.__exit__(*exc)

    def __call__(self, phase: str, temperature: float, samples: int, best: float) -> None:
        if not self.progress:
            return
        if phase == "posterior":
            description = f"posterior at the solution: {samples:,} samples"
        elif phase == "search":
            description = "searching"
        else:
            description = f"GA {phase}: T = {temperature:.3g}, N = {samples}, best log G = {best:.3f}"
        self.progress.update(self.task, description=description)


class _SampleProgress:
    """The posterior's samples drawn so far, on stderr (gone when the command ends). The bar
    starts with the first samples, so that a problem refused before any (too many samples, say)
    prints its message alone."""

    def __init__(self, samples: int, quiet: bool = False):
        from rich.progress import BarColumn, MofNCompleteColumn, Progress, TextColumn, TimeElapsedColumn

        self.progress = Progress(
            TextColumn("posterior"),
            BarColumn(),
            MofNCompleteColumn(),
            TimeElapsedColumn(),
            console=_console(True),
            transient=True,
            disable=quiet or not _console(True).is_terminal,  # as the solve's progress: a terminal's only
        )
        self.samples = samples
        self.task = None

    def __enter__(self):
        return self

    def __exit__(self, *exc):
        if self.task is not None:
            self.progress.__exit__(*exc)

    def __call__(self, done: int, samples: int) -> None:
        if self.task is None:
            self.progress.__enter__()
            self.task = self.progress.add_task("posterior", total=self.samples)
        self.progress.update(self.task, completed=done)


@app.command()
@_guarded
def solve(
    file: Path = typer.Argument(..., help="problem file (YAML)"),
    output: Path | None = typer.Option(None, "-o", "--output", help="write the JSON result here (default: stdout)"),
    seed: int = typer.Option(0, "--seed", help="random seed: the same seed gives the same numbers"),
    backend: str = typer.Option(
        "bayes",
        "--backend",
        metavar="[bayes|nominal]",
        help="bayes (the paper's method) or nominal (every L at nominal; a calibrated L at its MAP)",
    ),
    samples: str | None = typer.Option(
        None, "--samples", help="posterior samples, e.g. 1e5 (default: the problem's solver.posterior_samples)"
    ),
    estimator: str | None = typer.Option(
        None,
        "--estimator",
        metavar="[importance|linear|mc]",
        help="importance, linear or mc (default: the problem's solver.estimator, importance)",
    ),
    contributors: bool = typer.Option(
        False, "--contributors", metavar=" ", help="also print the contributors to each scored parameter's variance"
    ),
    quiet: bool = typer.Option(False, "--quiet", metavar=" ", help="no progress and no table, only the JSON"),
    as_json: bool = typer.Option(
        False,
        "--json",
        metavar=" ",
        help="print the JSON result on stdout (the table goes to stderr); the default without -o",
    ),
    samples_out: Path | None = typer.Option(
        None, "--samples-out", help="also write the posterior samples and weights here (.npz)"
    ),
    plot_dir: Path | None = typer.Option(
        None, "--plot", help="also draw the usual figures (arms, posterior, graph) into this folder (created if needed)"
    ),
    calibration: list[Path] = typer.Option([], "--calibration", metavar="RESULT", help=CALIBRATION_HELP),
) -> None:
    """Solve a problem: the X* that maximises p(X) I(X), then the closing links' posterior there.

    p(X) I(X): how likely a configuration X is, times how well the cell closes at X under every
    uncertain L (Eq. 2 of the 2000 paper); the posterior: each closing link's pose, its mean and
    std (the paper's Table 2)."""
    from bcad.arguments import COMMAND_LINE
    from bcad.bayes.arguments import run_options
    from bcad.bayes.run import solve_run
    from bcad.compiler.problem import input_files
    from bcad.io import check_output

    options = run_options(seed=seed, samples=samples, estimator=estimator, backend=backend, spelling=COMMAND_LINE)
    for target in (output, samples_out):
        if target is not None:
            check_output(target, [file, *calibration])  # before solving: a bad -o is reported at once
    compiled = _compile(file, calibration)
    inputs = input_files(file, compiled)
    _calibration_note(compiled)
    if plot_dir is not None:
        from bcad.plot import pyplot

        pyplot(file)  # the extra is there, or exit 2 before solving
        _plot_folder(plot_dir)
    with _GeneticProgress(quiet) as progress:
        result, kept = solve_run(
            compiled,
            options,
            COMMAND_LINE,
            progress=progress,
            samples_out=samples_out,
            inputs=inputs,
            output=output,
            keep=plot_dir is not None,
        )
    if plot_dir is not None:
        from bcad.bayes.result import DesignResult
        from bcad.io import write_bytes_atomic
        from bcad.plot.render import standard_figures

        skipped: list[str] = []
        figures = standard_figures(compiled, DesignResult.model_validate(result), kept or {}, file, skipped)
        for name, data in figures.items():
            write_bytes_atomic(data, plot_dir / f"{file.stem}_{name}.png", inputs)
        for note in skipped:
            _console(True).print(_plain(f"note: {note}"), soft_wrap=True)
    _finish(result, output, inputs, quiet, contributors, as_json=as_json or output is None)


def _json_on_stdout(as_json: bool, quiet: bool, output: Path | None) -> bool:
    """Whether the JSON result goes to stdout: with --json, or with --quiet and no -o (a result is
    never computed to be thrown away)."""
    return as_json or (quiet and output is None)


def _finish(
    result: dict, output: Path | None, protected: Path | list[Path], quiet: bool, contributors: bool, as_json: bool
) -> None:
    """Every command's output convention: ``-o`` writes the JSON result to a file, ``--json`` prints
    it on stdout, and the tables go to stdout unless the JSON does (then to stderr); ``--quiet``
    prints no table. Exit 3 if the result has warnings."""
    from bcad.bayes.document import search_line
    from bcad.bayes.result import DesignResult
    from bcad.report import configurations_table, contributors_table, posterior_table

    console = _console(as_json)
    typed = DesignResult.model_validate(result)
    if not quiet:
        console.print(posterior_table(typed))
        if typed.configurations is not None:
            console.print(configurations_table(typed))
        if contributors and typed.contributors is not None:
            console.print(contributors_table(typed))
        line = search_line(typed.diagnostics.get("search"), trusted=not typed.warnings)
        if line:
            console.print(_plain(line), soft_wrap=True)
    if output is not None:
        _write_json(result, output, protected)
    if as_json:
        _write_json(result, None, protected)
    _exit_on_warnings(typed)


def _exit_on_warnings(typed) -> None:
    """Print a typed result's design findings (information: exit 0) and warnings on stderr, and
    exit 3 if it has warnings (the result is already written)."""
    for finding in getattr(typed, "findings", None) or []:
        _console(True).print(_plain(f"finding [{finding.code}]: {finding.message}"), soft_wrap=True)
    for warning in typed.warnings:
        _console(True).print(_plain(f"warning [{warning.code}]: {warning.message}"), soft_wrap=True)
    if typed.warnings:
        raise typer.Exit(EXIT_UNTRUSTED)


def _deprecated(values: list[str], old: str, new: str, command: str) -> list[str]:
    """Values given with an option's former spelling: accepted, with a note on stderr."""
    if values:
        _console(True).print(
            f"{command}: {old} is deprecated, use {new} (the same values); {old} will be removed in the next release",
            style="yellow",
            soft_wrap=True,
        )
    return list(values)


def _plot_folder(folder: Path) -> None:
    """``--plot``'s folder, created if needed (as batch's ``--out``); a file there is refused."""
    if folder.exists() and not folder.is_dir():
        raise InputError(folder, "--plot: a file, not a folder")
    try:
        folder.mkdir(parents=True, exist_ok=True)
    except OSError as exc:
        raise InputError(folder, f"--plot: cannot create the folder: {exc.strerror or exc}") from None


def _parse_assignments(values: list[str]) -> dict[str, float]:
    assignments = {}
    for text in values:
        name, equals, value = text.partition("=")
        if equals and name.strip() in assignments:
            raise InputError("--value", f"{quoted(name.strip(), 40)} is given twice; give each X once")
        try:
            assignments[name.strip()] = float(value)
        except ValueError:
            equals = ""
        if equals and not math.isfinite(assignments[name.strip()]):
            raise InputError("--value", f"{quoted(text, 40)}: the value must be a finite number")
        if not equals:
            raise InputError("--value", f"{quoted(text, 40)} is not NAME=VALUE with a number")
    return assignments


@app.command()
@_guarded
def posterior(
    file: Path = typer.Argument(..., help="problem file (YAML)"),
    at: Path | None = typer.Option(None, "--at", help="a result JSON whose solution gives X"),
    assignments: list[str] = typer.Option(
        [], "--value", metavar="NAME=VALUE", help="an X parameter's value (repeatable; overrides --at)"
    ),
    old_assignments: list[str] = typer.Option([], "--set", hidden=True, help="the former spelling of --value"),
    samples: str | None = typer.Option(
        None,
        "--samples",
        help="number of posterior samples, e.g. 1e5 (default: the problem's solver.posterior_samples, as solve's)",
    ),
    seed: int = typer.Option(0, "--seed", help="random seed (with solve's seed and sample count: solve's posterior)"),
    estimator: str | None = typer.Option(
        None,
        "--estimator",
        metavar="[importance|linear|mc]",
        help="importance, linear or mc (default: the problem's solver.estimator)",
    ),
    contributors: bool = typer.Option(
        False, "--contributors", metavar=" ", help="also print the contributors to each scored parameter's variance"
    ),
    as_json: bool = typer.Option(
        False, "--json", metavar=" ", help="print the JSON result on stdout (the table goes to stderr)"
    ),
    output: Path | None = typer.Option(None, "-o", "--output", help="write the JSON result here"),
    quiet: bool = typer.Option(False, "--quiet", metavar=" ", help="no progress and no table"),
    samples_out: Path | None = typer.Option(
        None, "--samples-out", help="also write the posterior samples and weights here (.npz)"
    ),
    calibration: list[Path] = typer.Option([], "--calibration", metavar="RESULT", help=CALIBRATION_HELP),
) -> None:
    """The closing links' posterior at a given solution: each closing link's pose, its mean and std
    (Table 2 of the 2000 paper), and the estimate of log p(X) I(X) there."""
    from bcad.arguments import COMMAND_LINE
    from bcad.bayes.arguments import given_solution, run_options, solution_at
    from bcad.bayes.run import posterior_run
    from bcad.bayes.solvable import check_solvable
    from bcad.compiler.problem import input_files
    from bcad.io import check_output

    options = run_options(seed=seed, samples=samples, estimator=estimator, spelling=COMMAND_LINE)
    # the former spelling first: where both name an X, --value's value is the one kept (two
    # --value for one X are refused)
    values = _parse_assignments(_deprecated(old_assignments, "--set", "--value", "bcad posterior"))
    values.update(_parse_assignments(assignments))
    compiled = _compile(file, calibration)
    _calibration_note(compiled)
    check_solvable(compiled, needs_unknowns=False)
    given, source, units = given_solution(at, COMMAND_LINE)
    x = solution_at(compiled, given, values, COMMAND_LINE, source, units)
    inputs = input_files(file, compiled) + ([at] if at is not None else [])
    if output is not None:
        check_output(output, inputs)  # --samples-out: checked with the run (bcad.bayes.arguments.samples_kept)
    drawn = options.samples or compiled.problem.solver.posterior_samples
    with _SampleProgress(drawn, quiet) as progress:
        result = posterior_run(
            compiled, x, options, COMMAND_LINE, progress=progress, samples_out=samples_out, inputs=inputs, output=output
        )
    _finish(result, output, inputs, quiet, contributors, as_json=_json_on_stdout(as_json, quiet, output))


@app.command()
@_guarded
def calibrate(
    file: Path = typer.Argument(..., help="problem file with a measurements: section"),
    output: Path | None = typer.Option(None, "-o", "--output", help="write the JSON result here"),
    as_json: bool = typer.Option(
        False, "--json", metavar=" ", help="print the JSON result on stdout (the table goes to stderr)"
    ),
    quiet: bool = typer.Option(False, "--quiet", metavar=" ", help="no table"),
    robust: bool = typer.Option(
        False, "--robust", metavar=" ", help="Huber loss on each measurement row; report the outliers"
    ),
    check_samples: str = typer.Option(
        "auto",
        "--check-samples",
        help="importance samples checking the Laplace answer "
        "(0: no check, else at least 100; auto: 1,500,000 / measured values, within 1000..4000; "
        "fewer beyond 30,000 values)",
    ),
    seed: int = typer.Option(0, "--seed", help="random seed of the check"),
    urdf: Path | None = typer.Option(None, "--urdf", help="write the calibrated robot as a URDF here"),
    camera_info: Path | None = typer.Option(
        None,
        "--camera-info",
        help="write the calibrated camera as ROS camera_info YAML here (several cameras: FILE_CAMERA.yaml)",
    ),
    propose: int = typer.Option(
        0, "--propose", min=0, max=100_000, help="rank the K most informative --candidates (D-optimal)"
    ),
    candidates: Path | None = typer.Option(
        None, "--candidates", help="CSV of candidate configurations, a column per joint"
    ),
    predict: Path | None = typer.Option(
        None,
        "--predict",
        help="CSV of configurations (a column per joint): the calibrated model's readings there, each with its std",
    ),
    task: Path | None = typer.Option(
        None,
        "--for",
        help="with --propose: CSV of task configurations, or a planning problem "
        "(YAML) whose closing links' scored parameters are the task; propose what most "
        "reduces their predicted variance (not D-optimal)",
    ),
) -> None:
    """Calibrate: the identified parameters given the measurements (MAP, Laplace covariance,
    importance-sampling check)."""
    import time

    started = time.perf_counter()
    from bcad.arguments import COMMAND_LINE
    from bcad.calibration.run import calibrate_options

    text = check_samples.strip()
    options = calibrate_options(
        robust=robust,
        check_samples=None if text == "auto" else text,
        seed=seed,
        propose=propose,
        candidates=candidates,
        predict=predict,
        task=task,
        spelling=COMMAND_LINE,
    )
    from bcad.io import check_output

    for target in (output, urdf):
        if target is not None:
            check_output(target, [file] + [p for p in (candidates, predict, task) if p is not None])
    if output is not None and urdf is not None and output.resolve() == urdf.resolve():
        raise InputError("--urdf", "-o and --urdf name the same file")
    compiled = _compile(file)
    from bcad.api import nominal_configuration
    from bcad.calibration.report import calibration_table, prediction_table, proposal_table
    from bcad.calibration.run import calibration_run, output_files, write_calibrated

    # Inputs a result may not replace: the problem and the CSVs of the options, not read yet; the
    # robots' URDFs and the measurement data the problem names are recorded (bcad.io.record_input).
    inputs = [file] + [p for p in (candidates, predict, task) if p is not None]
    files = output_files(compiled, urdf, camera_info)
    targets = [t for t in [output, *files["urdf"].values(), *files["camera_info"].values()] if t is not None]
    if len({t.resolve() for t in targets}) < len(targets):
        raise InputError("-o, --urdf, --camera-info", "two outputs name the same file")
    for target in targets:
        check_output(target, inputs)
    from contextlib import nullcontext
    from dataclasses import asdict

    # a spinner on a terminal (nothing elsewhere, nothing with --quiet)
    with nullcontext() if quiet else _console(True).status(_plain("calibrating"), spinner="dots"):
        document, texts = calibration_run(
            compiled,
            urdf=urdf is not None,
            plan_configuration=nominal_configuration,
            started=started,
            **asdict(options),
        )
    write_calibrated(document, texts, files, inputs)
    to_stdout = _json_on_stdout(as_json, quiet, output)
    if not quiet:
        _console(to_stdout).print(calibration_table(document))
        if "proposal" in document:
            _console(to_stdout).print(proposal_table(document["proposal"]))
        if "prediction" in document:
            _console(to_stdout).print(prediction_table(document["prediction"]))
    if output is not None:
        _write_json(document, output, inputs)
    if to_stdout:
        _write_json(document, None, inputs)
    from bcad.calibration.result import CalibrationResult

    _exit_on_warnings(CalibrationResult.model_validate(document))


@app.command()
@_guarded
def detect(
    views: Path = typer.Argument(..., help="CSV of views: an image column (paths relative to it) and the joints"),
    checkerboard: str = typer.Option(
        ..., "--checkerboard", help="COLUMNSxROWS inner corners, e.g. 8x6 (OpenCV's pattern size)"
    ),
    output: Path = typer.Option(..., "-o", "--output", help="the detections CSV (joints, point, u, v)"),
) -> None:
    """Checkerboard corners in images, as a camera measurement's rows (needs the vision extra: OpenCV)."""
    import re

    from bcad.calibration.detect import MAX_CORNERS, MIN_CORNERS, detect_checkerboard, detections_text

    match = re.fullmatch(r"\s*(\d{1,9})\s*[xX]\s*(\d{1,9})\s*", checkerboard)
    if match is None or not all(MIN_CORNERS <= int(side) <= MAX_CORNERS for side in match.groups()):
        raise InputError(
            "--checkerboard",
            f"{quoted(checkerboard, 40)} is given; expected COLUMNSxROWS of inner corners, each from {MIN_CORNERS} to "
            f"{MAX_CORNERS} (8x6)",
        )
    from bcad.io import check_output, write_text_atomic

    check_output(output, [views])
    found = detect_checkerboard(views, int(match.group(1)), int(match.group(2)))
    write_text_atomic(detections_text(found), output, [views])
    _console(True).print(
        _plain(
            f"{found.views - len(found.missed)} of {found.views} views: {len(found.rows)} corners written to {output}"
        )
    )
    if found.missed:
        _console(True).print(
            _plain(
                f"warning [board_not_found]: no {checkerboard} board in {len(found.missed)} image(s): "
                f"{', '.join(found.missed[:5])}{' ...' if len(found.missed) > 5 else ''}"
            )
        )
        raise typer.Exit(3)


@app.command()
@_guarded
def plot(
    file: Path = typer.Argument(..., help="problem file (a clearance problem for --what error)"),
    what: str = typer.Option(
        ...,
        "--what",
        metavar="[arms|posterior|graph|relaxation|error|residuals]",
        help="arms, posterior, graph, relaxation, error, or residuals (a camera calibration's reprojection residuals)",
    ),
    at: list[Path] = typer.Option(
        [],
        "--at",
        metavar="RESULT",
        help="result JSON whose solution places the cell; give --at twice for two side by side",
    ),
    output: Path | None = typer.Option(
        None, "-o", "--output", help="the picture: .png, .svg (or .html for arms); default FILE_WHAT.png here"
    ),
    samples: str = typer.Option(
        "2e4", "--samples", help="posterior samples behind ellipsoids, corner plots and error sets"
    ),
    seed: int = typer.Option(0, "--seed", help="random seed of those samples"),
    link: str | None = typer.Option(None, "--link", help="the closing link of a corner plot (default: the first)"),
) -> None:
    """Draw a problem or a result (headless): the cell, a corner plot, the graph, a relation's relaxation
    (Fig. 2 of the 2000 paper), an error set."""
    from bcad.plot import KINDS

    if what not in KINDS:
        raise InputError("--what", f"{quoted(what, 40)} is not a picture; expected {', '.join(KINDS)}")
    count = _sample_count(samples, "--samples")
    from bcad.bayes.arguments import MAX_SAMPLES_OUT

    if count > MAX_SAMPLES_OUT:  # a picture keeps its samples in memory
        raise InputError("--samples", f"at most {MAX_SAMPLES_OUT:.0e} samples behind a picture")
    if len(at) > 2:
        raise InputError("--at", "at most two results (side by side)")
    output = output or Path(f"{file.stem}_{what}.png")
    suffix = output.suffix.lower()
    if suffix not in (".png", ".svg", ".html") or (suffix == ".html" and what != "arms"):
        raise InputError("-o", f"{quoted(str(output), 60)}: expected .png or .svg (or .html for --what arms)")
    from bcad.io import check_output

    check_output(output, [file, *at])
    from bcad.arguments import COMMAND_LINE, random_seed
    from bcad.plot.render import render

    seed = random_seed(seed, COMMAND_LINE)
    data = render(file, what, at=at, samples=count, seed=seed, link=link, suffix=suffix)
    from bcad.io import write_bytes_atomic

    write_bytes_atomic(data, output, [file, *at])
    _console(True).print(_plain(f"wrote {output}"))


@app.command()
@_guarded
def schema(
    results: bool = typer.Option(
        False, "--results", metavar=" ", help="the schema of the result documents instead (schema/results.schema.json)"
    ),
) -> None:
    """Print the JSON Schema of the problem language (for editors: see schema/bcad.schema.json)."""
    if results:
        from bcad.result import results_json_schema

        document = results_json_schema()
    else:
        from bcad.model.schema import problem_json_schema

        document = problem_json_schema()
    sys.stdout.write(json.dumps(document, indent=2, sort_keys=True) + "\n")


@app.command()
@_guarded
def maxerror(
    file: Path = typer.Argument(..., help="clearance problem (YAML with chain and clearance)"),
    as_json: bool = typer.Option(
        False, "--json", metavar=" ", help="print the JSON result on stdout (the table goes to stderr)"
    ),
    output: Path | None = typer.Option(None, "-o", "--output", help="write the JSON result here"),
    tol: float = typer.Option(1e-6, "--tol", help="relative gap (upper_bound - max) / upper_bound to reach"),
    model: str = typer.Option(
        "first-order",
        "--model",
        metavar="[first-order|exact]",
        help="first-order (certified), or exact (adds a search on the exact error, Eq. 10 of the 2010 paper)",
    ),
    samples: str | None = typer.Option(
        None, "--samples", help="also sample uniformly distributed clearances, e.g. 1e5"
    ),
    seed: int = typer.Option(0, "--seed", help="random seed of --samples"),
    quiet: bool = typer.Option(False, "--quiet", metavar=" ", help="no table"),
    spec: str | None = typer.Option(
        None,
        "--spec",
        help="the yield of a spec, e.g. rotation=0.001,translation=0.0004 "
        "(and dx, dy, dz, -dx, -dy, -dz: the tool's displacement along a base axis) "
        "(problem units; samples 1e5 unless --samples says)",
    ),
    allocate: str | None = typer.Option(
        None,
        "--allocate",
        help="tolerance synthesis: the largest scale of the clearances "
        "whose exact errors meet this spec, e.g. translation=0.0004 or dx=0.09 (a wall; certified bracket)",
    ),
    weights: str | None = typer.Option(
        None, "--weights", help="with --allocate: per-joint weights of the scale, e.g. 1,1,2"
    ),
) -> None:
    """Largest end-effector rotation and translation error that joint clearances can cause (certified)."""
    from bcad.arguments import COMMAND_LINE
    from bcad.worstcase.run import maxerror_options, maxerror_with

    options = maxerror_options(
        tol=tol,
        model=model,
        samples=samples,
        spec=spec,
        allocate=allocate,
        weights=weights,
        seed=seed,
        spelling=COMMAND_LINE,
    )
    if output is not None:
        from bcad.io import check_output

        check_output(output, [file])
    from bcad.model.clearance import load_chain_problem
    from bcad.report import maxerror_table
    from bcad.worstcase.result import MaxErrorResult

    problem = load_chain_problem(file)
    document = maxerror_with(problem, options)
    if output is not None:
        _write_json(document, output, file)
    to_stdout = _json_on_stdout(as_json, quiet, output)
    typed = MaxErrorResult.model_validate(document)
    if not quiet:
        _console(to_stdout).print(maxerror_table(typed))
    if to_stdout:
        _write_json(document, None, file)
    _exit_on_warnings(typed)


@app.command()
@_guarded
def batch(
    files: list[Path] = typer.Argument(
        ..., help="problem files: Bayesian problems are solved, clearance chains get maxerror"
    ),
    out: Path = typer.Option(..., "--out", help="folder for the results (created if needed)"),
    seed: int = typer.Option(
        0, "--seed", help="base seed; each problem's seed derives from it, its file name and sweep point"
    ),
    jobs: int | None = typer.Option(None, "--jobs", help="local worker processes (default: the number of cores)"),
    scheduler: str | None = typer.Option(None, "--scheduler", help="run on a Dask scheduler, e.g. tcp://host:8786"),
    resume: bool = typer.Option(
        False, "--resume", metavar=" ", help="skip problems whose result already exists and is complete"
    ),
    sweeps: list[str] = typer.Option(
        [], "--sweep", metavar="KEY=V1,V2,...", help="sweeps a dotted key of the problem (repeat for a grid)"
    ),
    old_sweeps: list[str] = typer.Option([], "--set", hidden=True, help="the former spelling of --sweep"),
    quiet: bool = typer.Option(False, "--quiet", metavar=" ", help="no progress bar"),
    timeout: float | None = typer.Option(
        None, "--timeout", help="seconds a problem may run before it is stopped and recorded as failed (local runs)"
    ),
    plot_dir: Path | None = typer.Option(
        None,
        "--plot",
        help="also draw each sweep's key figure against its value, and each solved cell, into this folder "
        "(created if needed)",
    ),
) -> None:
    """Run many problems (and sweeps) locally or on a Dask cluster; exit 1 if any failed, 3 if any has warnings."""
    from bcad.batch import BatchUsageError, check_scheduler_address, parse_sweep, plan_tasks, run_batch

    try:
        if jobs is None:
            jobs = os.cpu_count() or 1
        if jobs < 1:
            raise BatchUsageError(f"--jobs must be at least 1, got {jobs}")
        if timeout is not None and not (math.isfinite(timeout) and 0 < timeout <= 1e6):
            raise BatchUsageError(f"--timeout must be a number of seconds in (0, 1e6], got {timeout}")
        if scheduler is not None:
            check_scheduler_address(scheduler)
        if out.exists() and not out.is_dir():
            raise BatchUsageError(f"--out {out} is a file, expected a folder")
        sweeps = sweeps + _deprecated(old_sweeps, "--set", "--sweep", "bcad batch")
        from bcad.arguments import COMMAND_LINE, random_seed

        tasks = plan_tasks(
            list(files), out, random_seed(seed, COMMAND_LINE), [parse_sweep(text) for text in sweeps], timeout
        )
        if plot_dir is not None:
            from bcad.plot import pyplot

            pyplot(plot_dir)  # the extra is there, or exit 2 before running
            _plot_folder(plot_dir)
        try:
            out.mkdir(parents=True, exist_ok=True)
        except OSError as exc:
            raise BatchUsageError(f"cannot create --out {out}: {exc.strerror or exc}") from None
        if scheduler is not None:
            from bcad.batch import require_dask

            require_dask()
        from rich.progress import BarColumn, MofNCompleteColumn, Progress, TextColumn, TimeElapsedColumn

        with Progress(
            TextColumn("{task.description}", markup=False),
            BarColumn(),
            MofNCompleteColumn(),
            TimeElapsedColumn(),
            console=_console(True),
            disable=quiet or not _console(True).is_terminal,  # a terminal's only, as the other commands'
            transient=False,
        ) as progress:
            bar = progress.add_task("batch", total=len(tasks))

            def done(line: dict) -> None:
                progress.update(bar, advance=1, description=f"{line['output']}: {line['status']}")

            outcome = run_batch(tasks, jobs=jobs, scheduler=scheduler, resume=resume, on_done=done)
    except BatchUsageError as exc:
        _console(True).print(_plain(f"bcad batch: {exc}"), soft_wrap=True)
        raise typer.Exit(EXIT_INPUT) from None
    if plot_dir is not None:
        _batch_figures(outcome.summaries, tasks, plot_dir)
    if not quiet:
        for line in outcome.summaries:
            if line["status"] == "error":
                _console(True).print(_plain(f"{line['output']}: {line['error']['message']}"), soft_wrap=True)
        _console(True).print(
            f"{len(outcome.summaries) - outcome.failed} of {len(outcome.summaries)} problems done, "
            f"{outcome.failed} failed, "
            f"{outcome.warned} with warnings; summary in {out / 'summary.jsonl'}",
            highlight=False,
            markup=False,
        )
    if outcome.failed:
        raise typer.Exit(1)
    if outcome.warned:
        raise typer.Exit(EXIT_UNTRUSTED)


def _batch_figures(summaries: list[dict], tasks, folder: Path) -> None:
    """``batch --plot``: a line plot per sweep, and the cell at each solved problem's solution."""
    import re

    from bcad.batch import short_stem
    from bcad.io import write_bytes_atomic
    from bcad.plot.render import figure_bytes
    from bcad.plot.sweep import draw_sweep, sweep_series

    for (name, key), slices in sweep_series(summaries).items():
        figure, _ = draw_sweep(name, key, slices, folder)
        safe = short_stem(re.sub(r"[^A-Za-z0-9_.=-]+", "_", f"{Path(name).stem}__{key}"))
        write_bytes_atomic(figure_bytes(figure, ".png"), folder / f"{safe}.png")
    from bcad.batch import task_document
    from bcad.bayes.result import DesignResult
    from bcad.compiler import compile_problem
    from bcad.model.problem import problem_from_document
    from bcad.plot.render import standard_figures

    for task, line in zip(tasks, summaries):
        if line.get("status") == "error" or line.get("kind") != "solve":
            continue
        try:
            result = DesignResult.model_validate_json(Path(task.output).read_text(encoding="utf-8"))
            compiled = compile_problem(problem_from_document(task_document(task)))
            figures = standard_figures(compiled, result, {}, task.file)
        except (OSError, ValueError, InputError):
            continue  # the result is the batch's; a picture it cannot draw is skipped
        write_bytes_atomic(figures["arms"], folder / (Path(task.output).stem + "_arms.png"))


def _version(value: bool) -> None:
    if value:
        try:
            print(f"bcad {__version__}", flush=True)
        except OSError as exc:  # a full device or a closed pipe: exit 2 as every command (click's own would be 1)
            if exc.errno not in OUTPUT_ERRORS:
                raise
            _output_failed(exc)
        raise typer.Exit()


@app.callback()
def _root(
    ctx: typer.Context,
    version: bool = typer.Option(False, "--version", callback=_version, is_eager=True, help="print the version"),
    confine: Path | None = typer.Option(
        None,
        "--confine",
        metavar="DIR",
        help="read files only from DIR (problems, robots, CSVs, results, meshes; "
        "links resolved) and refuse xacro files: for running problems others wrote (also: BCAD_CONFINE=DIR)",
    ),
) -> None:
    from bcad.runtime import tune_allocator

    tune_allocator()
    if confine is not None:
        from bcad.model.source import confined

        if not confine.is_dir():
            raise typer.BadParameter(f"'{confine}' is not a folder", param_hint="--confine")
        # for the command's run (a batch's tasks carry the folder to their workers)
        ctx.with_resource(confined(confine))


def main() -> None:
    import warnings

    # Non-finite intermediate values are handled (log-space sums, -inf weights) and what a
    # user must know is in the result's warnings: numpy's RuntimeWarnings would only leak
    # source lines onto stderr.
    warnings.simplefilter("ignore", RuntimeWarning)
    # A terminal or pipe that cannot show a character of a name (an ASCII-only locale) shows
    # its escape (\\xfc) instead of failing the command; JSON is ASCII already.
    for stream in (sys.stdout, sys.stderr):
        try:
            stream.reconfigure(errors="backslashreplace")
        except (AttributeError, ValueError):
            pass  # not a text stream bcad can reconfigure (a test's capture): left as it is
    # typer's own output (--help, --version, usage errors) to a full device or a closed
    # pipe: one line and exit 2, not a traceback, here or when the exit flushes stdout.
    try:
        try:
            app()
        finally:
            sys.stdout.flush()
    except OSError as exc:
        if exc.errno not in OUTPUT_ERRORS:
            raise
        _report_output_failure(exc)
        sys.exit(EXIT_INPUT)


if __name__ == "__main__":
    main()
