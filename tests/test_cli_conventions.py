"""One output convention for every command that writes a result (solve, posterior, calibrate,
maxerror): ``-o FILE`` writes the JSON result to FILE, ``--json`` prints it on stdout, the table
goes to stdout unless the JSON does (then to stderr), ``--quiet`` prints no table. Former
spellings still work, with a note."""

from __future__ import annotations

import json

import pytest

from conftest import ONE_LINK_GRAPH, REPO, run_bcad


@pytest.fixture
def commands(write_problem):
    problem = write_problem(ONE_LINK_GRAPH)
    return {
        "solve": ["solve", problem, "--samples", "2e3"],
        "posterior": ["posterior", problem, "--value", "unknown.tx=2.8", "--samples", "2e3"],
        "calibrate": ["calibrate", REPO / "problems" / "calibration" / "rx90_sphere_touches.yaml"],
        "maxerror": ["maxerror", REPO / "problems" / "clearance" / "2r.yaml"],
    }


TABLE_WORDS = {"solve": "Table 2", "posterior": "Table 2", "calibrate": "calibrated", "maxerror": "rotation"}


@pytest.mark.parametrize("command", list(TABLE_WORDS))
def test_json_goes_to_stdout_and_the_table_to_stderr(command, commands):
    run = run_bcad(*commands[command], "--json")
    assert run.returncode == 0, run.stderr
    assert isinstance(json.loads(run.stdout), dict)
    assert TABLE_WORDS[command] in run.stderr


@pytest.mark.parametrize("command", list(TABLE_WORDS))
def test_o_writes_the_json_and_the_table_goes_to_stdout(command, commands, tmp_path):
    out = tmp_path / "result.json"
    run = run_bcad(*commands[command], "-o", out)
    assert run.returncode == 0, run.stderr
    assert isinstance(json.loads(out.read_text()), dict)
    assert TABLE_WORDS[command] in run.stdout and not run.stdout.lstrip().startswith("{")
    quiet = run_bcad(*commands[command], "-o", tmp_path / "again.json", "--quiet")
    assert quiet.returncode == 0 and quiet.stdout == ""
    assert json.loads((tmp_path / "again.json").read_text()).keys() == json.loads(out.read_text()).keys()


@pytest.mark.parametrize("command", list(TABLE_WORDS))
def test_o_and_json_together_write_both(command, commands, tmp_path):
    out = tmp_path / "result.json"
    run = run_bcad(*commands[command], "-o", out, "--json")
    assert run.returncode == 0, run.stderr
    assert json.loads(run.stdout).keys() == json.loads(out.read_text()).keys()


@pytest.mark.parametrize("command", list(TABLE_WORDS))
def test_quiet_alone_prints_the_json_and_nothing_else(command, commands):
    """--quiet with neither -o nor --json: the JSON on stdout, no table (it printed nothing on
    posterior and maxerror: the result was computed and thrown away)."""
    run = run_bcad(*commands[command], "--quiet")
    assert run.returncode == 0, run.stderr
    assert isinstance(json.loads(run.stdout), dict) and TABLE_WORDS[command] not in run.stderr


def test_value_wins_over_the_former_set_for_the_same_x(commands):
    posterior = commands["posterior"][:2] + ["--set", "unknown.tx=2.5", "--value", "unknown.tx=2.8", "--samples", "2e3"]
    run = run_bcad(*posterior, "--json")
    assert run.returncode == 0 and json.loads(run.stdout)["solution"] == {"unknown.tx": 2.8}


def test_solve_without_o_prints_its_json_as_the_quick_start_shows(commands):
    run = run_bcad(*commands["solve"])
    assert run.returncode == 0 and "objective" in json.loads(run.stdout) and "Table 2" in run.stderr


def test_the_former_set_spellings_still_work_with_a_note(commands, tmp_path):
    posterior = [word if word != "--value" else "--set" for word in commands["posterior"]]
    run = run_bcad(*posterior, "--json")
    assert run.returncode == 0 and json.loads(run.stdout)["solution"] == {"unknown.tx": 2.8}
    assert "--set is deprecated, use --value" in " ".join(run.stderr.split())
    problem = commands["solve"][1]
    batch = run_bcad(
        "batch",
        problem,
        "--out",
        tmp_path / "out",
        "--jobs",
        "1",
        "--quiet",
        "--set",
        "solver.posterior_samples=1000,2000",
    )
    assert batch.returncode == 0, batch.stderr
    assert "--set is deprecated, use --sweep" in " ".join(batch.stderr.split())
    assert len((tmp_path / "out" / "summary.jsonl").read_text().splitlines()) == 2


def test_help_lists_choices_and_no_default_of_the_machine_that_built_it():
    solve = run_bcad("solve", "--help", env_extra={"COLUMNS": "200"}).stdout
    assert "[bayes|nominal]" in solve and "[importance|linear|mc]" in solve
    assert "[first-order|exact]" in run_bcad("maxerror", "--help", env_extra={"COLUMNS": "200"}).stdout
    batch = run_bcad("batch", "--help", env_extra={"COLUMNS": "200"}).stdout
    line = next(line for line in batch.splitlines() if "--jobs" in line)
    assert "default: the number of cores" in line and "[default: " not in line


def test_help_lists_the_exit_codes_the_guide_gives():
    """`bcad --help` names each exit code with the meaning the commands guide gives it."""
    import re

    from conftest import REPO

    guide = (REPO / "docs" / "guide" / "commands.md").read_text()
    documented = dict(re.findall(r"`([0-3])` (success|invalid input|a result|an internal error)", guide))
    assert set(documented) == {"0", "1", "2", "3"}, documented
    text = " ".join(run_bcad("--help").stdout.split())
    listed = dict(re.findall(r"([0-3]) (success|invalid input|a result|an internal error)", text))
    assert listed == documented, text


@pytest.mark.parametrize(
    ("arguments", "absent"),
    [
        (["--help"], {"rich", "numpy", "pydantic", "scipy", "yaml"}),
        (["--version"], {"rich", "numpy", "pydantic", "scipy", "yaml"}),
        # typer reads a command's options through pydantic where it is installed: its cost, not bcad's
        (["solve", "--help"], {"rich", "numpy", "scipy", "yaml"}),
    ],
)
def test_help_and_version_import_neither_rich_nor_the_numerics(arguments, absent):
    """`bcad --help` and `--version` print typer's text alone: rich, numpy and pydantic (most of
    a command's start-up) are imported by the commands that use them."""
    import subprocess
    import sys

    script = (
        "import sys, runpy\n"
        f"sys.argv = ['bcad', *{arguments!r}]\n"
        "try:\n"
        "    runpy.run_module('bcad.cli', run_name='__main__')\n"
        "except SystemExit:\n"
        "    pass\n"
        f"heavy = sorted({{m.split('.')[0] for m in sys.modules}} & set({sorted(absent)!r}))\n"
        "print('imported:', heavy, file=sys.stderr)\n"
    )
    run = subprocess.run([sys.executable, "-c", script], capture_output=True, text=True, timeout=60)
    assert run.stdout.strip(), run.stderr
    assert "imported: []" in run.stderr, run.stderr


def test_posterior_draws_what_solve_drew_by_default(tmp_path):
    """Without --samples, posterior draws the problem's solver.posterior_samples, as solve does,
    so the same seed gives solve's posterior number for number (planar_2r: 20000, not 1e5)."""
    problem = REPO / "problems" / "studies" / "planar_2r.yaml"
    solved = tmp_path / "planar.json"
    assert run_bcad("solve", problem, "-o", solved, "--quiet").returncode == 0
    again = run_bcad("posterior", problem, "--at", solved, "--json")
    assert again.returncode == 0, again.stderr
    first, second = json.loads(solved.read_text())["posterior"], json.loads(again.stdout)["posterior"]
    assert second["samples"] == 20000 and second["links"] == first["links"]


def test_a_posterior_refused_before_any_sample_prints_its_message_alone(tmp_path):
    """Too many samples for the problem: exit 2 with the message, and no progress bar's remains
    (the bar starts with the first samples drawn)."""
    problem = REPO / "problems" / "studies" / "planar_2r.yaml"
    solved = tmp_path / "planar.json"
    assert run_bcad("solve", problem, "-o", solved, "--quiet").returncode == 0
    refused = run_bcad("posterior", problem, "--at", solved, "--samples", "1e9", env_extra={"COLUMNS": "200"})
    assert refused.returncode == 2
    assert refused.stderr.startswith("--samples: 1,000,000,000 posterior samples"), repr(refused.stderr[:80])
    assert "would take more than about half a minute; at most 15,384,615 are taken" in refused.stderr


def test_piped_stderr_carries_no_progress_remains(tmp_path):
    """Where stderr is a pipe (a script, a log file), a solve draws no progress display: a solve
    that writes its result with -o leaves stderr empty, and one refused before it starts prints its
    message as the first line, not after a blank one."""
    problem = REPO / "problems" / "studies" / "planar_2r.yaml"
    run = run_bcad("solve", problem, "-o", tmp_path / "planar.json")
    assert run.returncode == 0 and run.stderr == "", repr(run.stderr[:80])
    text = problem.read_text()
    assert "solver: {posterior_samples: 20000}" in text
    huge = tmp_path / "huge.yaml"
    huge.write_text(text.replace("posterior_samples: 20000", "posterior_samples: 1000000000"))
    refused = run_bcad("solve", huge, "-o", tmp_path / "huge.json")
    assert refused.returncode == 2
    assert refused.stderr.startswith(f"{huge}:"), repr(refused.stderr[:80])
