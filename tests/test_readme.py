"""The README: its quick start is two commands, its twenty-line problem is the example file and
its output is what bcad prints; the language guide's annotated example is a valid problem."""

from __future__ import annotations

import re

from bcad.compiler import compile_problem
from bcad.model import load_problem

from conftest import REPO, RX90_URDF, documentation

README = (REPO / "README.md").read_text(encoding="utf-8")
LANGUAGE = (REPO / "docs" / "guide" / "language.md").read_text(encoding="utf-8")


def test_annotated_example_is_valid(write_problem):
    example = re.search(r"```yaml\n(.*?)```", LANGUAGE, re.S).group(1)
    example = example.replace("../robots/rx90.urdf", str(RX90_URDF))
    compiled = compile_problem(load_problem(write_problem(example)))
    stats = compiled.stats
    # X: fixture.rz and joints 1-5 (joint 6 is F); L: base (3), zeros (6),
    # fixture tx,ty (2), tool tz (1), and the relation's tz is scored, not integrated.
    assert stats.optimization_dim == 6
    assert stats.integration_dim == 12
    assert stats.cycles == 1
    assert stats.inequality_constraints == 4
    assert compiled.parameters.x_bounds[compiled.parameters.x_names.index("arm/joint_1.rz")] == (-1.0, 1.0)


def test_quick_start_is_two_commands():
    block = re.search(r"## Quick start\n\n```bash\n(.*?)```", README, re.S).group(1)
    commands = [line for line in block.splitlines() if line.strip()]
    assert commands == [
        "python -m pip install -e . && bcad solve problems/rx90_face_on_face.yaml",
        "python -m pip install -e '.[test]' && python -m pytest",
    ]


def test_quick_start_demo_runs_from_the_command_line(tmp_path_factory):
    """The quick start's `bcad solve problems/rx90_face_on_face.yaml`: a trusted result (exit 0),
    the JSON on stdout and the table on stderr."""
    import json

    from conftest import quick_start_solved

    run = quick_start_solved(tmp_path_factory)
    stderr = (run / "stderr.txt").read_text(encoding="utf-8")
    assert (run / "returncode").read_text() == "0", stderr
    result = json.loads((run / "result.json").read_text(encoding="utf-8"))
    assert result["warnings"] == [] and result["objective"]["estimator"] == "importance"
    assert "Table 2" in stderr


def test_readme_batch_command_runs(tmp_path):
    import shutil

    from conftest import run_bcad

    line = next(
        line for line in documentation().splitlines() if line.startswith("bcad batch problems/rx90_face_on_face.yaml")
    )
    assert line == "bcad batch problems/rx90_face_on_face.yaml problems/clearance/*.yaml --out results"
    files = ["problems/rx90_face_on_face.yaml"] + sorted(
        str(p.relative_to(REPO)) for p in (REPO / "problems" / "clearance").glob("*.yaml")
    )
    run = run_bcad("batch", *files, "--out", str(tmp_path / "results"), "--quiet", cwd=REPO)
    assert run.returncode == 0, run.stderr
    lines = (tmp_path / "results" / "summary.jsonl").read_text().splitlines()
    assert len(lines) == len(files)
    shutil.rmtree(tmp_path / "results")


def test_nominal_backend_closes_the_annotated_example(write_problem):
    """bcad's Levenberg-Marquardt stalls on this one from the file's start (a kink of the
    square's constraints near it): the nominal backend's batched restarts close it, and from
    the file's start alone scipy's trust-region fallback does."""
    import numpy as np

    from bcad.bayes.closure import CycleClosure
    from bcad.bayes.model import BayesModel
    from bcad.bayes.nominal import solve_nominal
    from bcad.numerics.least_squares import CLOSED

    example = re.search(r"```yaml\n(.*?)```", LANGUAGE, re.S).group(1).replace("../robots/rx90.urdf", str(RX90_URDF))
    compiled = compile_problem(load_problem(write_problem(example)))
    model = BayesModel(compiled)
    solution = solve_nominal(model, np.random.default_rng(0))
    assert solution.closed and solution.starts == 21
    closure = CycleClosure(compiled, model.objective)
    start = np.array(compiled.parameters.x_nominal)
    assert closure.close(start, fallback=False)[1] >= CLOSED
    assert closure.close(start)[1] < CLOSED


def test_readme_confined_batch_runs(tmp_path):
    """The README's confined batch: every file inside the folder, so every task runs; the same
    batch confined to problems/clearance refuses the RX90 cells' robots (in robots/)."""
    import json

    from conftest import run_bcad

    line = next(line for line in documentation().splitlines() if line.startswith("bcad --confine"))
    assert line.split("#")[0].split() == [
        "bcad",
        "--confine",
        ".",
        "batch",
        "problems/clearance/*.yaml",
        "--out",
        "results",
    ]
    files = sorted(str(p.relative_to(REPO)) for p in (REPO / "problems" / "clearance").glob("*.yaml"))
    run = run_bcad("--confine", ".", "batch", *files, "--out", str(tmp_path / "results"), "--quiet", cwd=REPO)
    assert run.returncode == 0, run.stderr
    run = run_bcad(
        "--confine", "problems/clearance", "batch", *files, "--out", str(tmp_path / "narrow"), "--quiet", cwd=REPO
    )
    status = {
        json.loads(line)["file"]: json.loads(line)["status"]
        for line in (tmp_path / "narrow" / "summary.jsonl").read_text().splitlines()
    }
    assert run.returncode == 1 and status["rx90_work.yaml"] == "error" and status["7r.yaml"] == "ok"


def test_the_readme_problem_is_the_example_file():
    """The twenty-line problem the README shows is problems/studies/planar_2r.yaml, key for key."""
    import yaml

    shown = yaml.safe_load(re.search(r"## A problem in twenty lines\n.*?```yaml\n(.*?)```", README, re.S).group(1))
    assert shown == yaml.safe_load((REPO / "problems" / "studies" / "planar_2r.yaml").read_text(encoding="utf-8"))


def test_the_readme_output_is_what_bcad_prints(tmp_path):
    """The table the README shows under its command is what that command prints at seed 0: the
    same rows of figures (the table's words may wrap differently on another terminal)."""
    from conftest import run_bcad

    block = re.search(r"## A problem in twenty lines\n.*?```console\n(.*?)```", README, re.S).group(1)
    command, *shown = block.splitlines()
    assert command == "$ bcad solve problems/studies/planar_2r.yaml -o planar.json"
    run = run_bcad(
        "solve",
        "problems/studies/planar_2r.yaml",
        "-o",
        str(tmp_path / "planar.json"),
        cwd=REPO,
        env_extra={"COLUMNS": "80"},
    )
    assert run.returncode == 0, run.stderr
    rows = [line for line in shown if line.startswith("│")]
    printed = run.stdout + run.stderr  # with -o the table goes to stdout
    assert len(rows) == 8 and all(row in printed for row in rows), printed
    objective = next(line for line in shown if line.startswith("log p(X) I(X)"))
    assert objective.split(" (")[0] in " ".join(printed.split())
    # the search's line too (it said 40 climbs where the command printed 39), its words rewrapped
    search = " ".join(" ".join(shown[next(k for k, line in enumerate(shown) if line.startswith("search:")) :]).split())
    assert search in " ".join(printed.split()), (search, printed)


def test_the_readme_posterior_command_agrees_with_the_solve_it_follows(tmp_path):
    """The README's `bcad posterior ... --at planar.json --samples 1e6`: the same objective as the
    solve it re-evaluates, within the two standard errors."""
    import json
    import math

    from conftest import run_bcad

    text = " ".join(README.split())
    assert "`bcad posterior problems/studies/planar_2r.yaml --at planar.json --samples 1e6`" in text
    solved = tmp_path / "planar.json"
    assert run_bcad("solve", "problems/studies/planar_2r.yaml", "-o", solved, "--quiet", cwd=REPO).returncode == 0
    run = run_bcad(
        "posterior", "problems/studies/planar_2r.yaml", "--at", solved, "--samples", "1e6", "--json", cwd=REPO
    )
    assert run.returncode == 0, run.stderr
    first, again = json.loads(solved.read_text())["objective"], json.loads(run.stdout)["objective"]
    assert again["samples"] == 1_000_000
    se = math.hypot(first["log_value_se"], again["log_value_se"])
    assert abs(first["log_value"] - again["log_value"]) < 4 * se


def test_the_search_budgets_the_readme_states_are_the_rx90_examples(tmp_path_factory):
    """The README's 120 screened starts and 24 climbs on the RX90 example, and its table line's 73
    climbs from 361 screened starts: the default budget, and a seed-0 solve's diagnostics."""
    import json

    from bcad.bayes.estimators import search_budget

    from conftest import RX90_EXAMPLE, rx90_solved

    words = " ".join(README.split())
    assert "120 and 24 on the RX90 example" in words and "73 climbs from 361 screened starts" in words
    compiled = compile_problem(load_problem(RX90_EXAMPLE))
    parameters = compiled.parameters
    assert search_budget(compiled.problem.solver, len(parameters.x), len(parameters.l)) == (120, 24)
    search = json.loads(rx90_solved(tmp_path_factory).read_text())["diagnostics"]["search"]
    assert (search["climbs"], search["starts"]) == (73, 361)
