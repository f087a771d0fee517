"""The ``bcad`` command line.

Exit codes: 0 success, 1 internal error, 2 invalid input or command line.
Results go to stdout (or a file); messages and progress go to stderr.
"""

from __future__ import annotations

import functools
import json
import os
import sys
from pathlib import Path
from typing import Callable

import typer
from rich.console import Console

from bcad import __version__
from bcad.errors import InputError

app = typer.Typer(
    add_completion=False,
    no_args_is_help=True,
    help="bcad: Bayesian robotic CAD. Problems are YAML files; see the README for the language.",
)
stdout = Console()
stderr = Console(stderr=True)

EXIT_INPUT = 2
EXIT_INTERNAL = 1


def _guarded(command: Callable) -> Callable:
    """Turn bcad's errors into a one-line message and an exit code, never a traceback."""

    @functools.wraps(command)
    def wrapper(*args, **kwargs):
        try:
            return command(*args, **kwargs)
        except InputError as exc:
            stderr.print(str(exc), highlight=False, markup=False, soft_wrap=True)
            raise typer.Exit(EXIT_INPUT) from None
        except (typer.Exit, typer.Abort, KeyboardInterrupt):
            raise
        except Exception as exc:  # a bug in bcad, not in the input
            if os.environ.get("BCAD_DEBUG"):
                raise
            stderr.print(
                f"[red]internal error[/red]: {type(exc).__name__}: {exc} "
                "(set BCAD_DEBUG=1 for the traceback, and please report it)",
                highlight=False,
                soft_wrap=True,
            )
            raise typer.Exit(EXIT_INTERNAL) from None

    return wrapper


def _compile(path: Path):
    from bcad.compile import compile_problem
    from bcad.model import load_problem

    return compile_problem(load_problem(path))


@app.command()
@_guarded
def validate(
    file: Path = typer.Argument(..., help="problem file (YAML)"),
    as_json: bool = typer.Option(False, "--json", help="print the statistics as JSON"),
) -> None:
    """Validate a problem and print its statistics (Table 1 of the 2000 paper)."""
    compiled = _compile(file)
    if as_json:
        sys.stdout.write(json.dumps({"stats": compiled.stats.as_dict()}, indent=2) + "\n")
        return
    from bcad.report import stats_table

    stdout.print(stats_table(compiled))


@app.command()
@_guarded
def graph(
    file: Path = typer.Argument(..., help="problem file (YAML)"),
    dot: bool = typer.Option(False, "--dot", help="write Graphviz DOT instead of a tree"),
) -> None:
    """Show the spanning tree and the cycles with their closing links."""
    compiled = _compile(file)
    from bcad.report import graph_dot, graph_tree

    if dot:
        sys.stdout.write(graph_dot(compiled))
    else:
        stdout.print(graph_tree(compiled))


def _version(value: bool) -> None:
    if value:
        print(f"bcad {__version__}")
        raise typer.Exit()


@app.callback()
def _root(
    version: bool = typer.Option(False, "--version", callback=_version, is_eager=True, help="print the version"),
) -> None:
    from bcad.runtime import tune_allocator

    tune_allocator()


def main() -> None:
    app()


if __name__ == "__main__":
    main()
