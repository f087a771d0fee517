"""The documentation: every tutorial runs end to end as written, the generated reference pages
are current, the site builds with warnings as errors, and no page or comment speaks of how bcad
was made rather than of what it does."""

from __future__ import annotations

import re
import shlex
import shutil
import subprocess
import sys

import pytest

from conftest import DOCS, REPO, run_bcad

TUTORIALS = sorted(page for page in (DOCS / "tutorials").glob("*.md") if page.stem != "index")


def _blocks(page, language: str) -> list[str]:
    return re.findall(rf"^```{language}\n(.*?)^```", page.read_text(encoding="utf-8"), re.S | re.M)


def _commands(page) -> list[str]:
    return [line[2:] for block in _blocks(page, "console") for line in block.splitlines() if line.startswith("$ ")]


def test_every_tutorial_is_listed_and_shows_commands():
    index = (DOCS / "tutorials" / "index.md").read_text(encoding="utf-8")
    for page in TUTORIALS:
        assert f"\n{page.stem}\n" in index, f"{page.name} is not in the tutorials' table of contents"
        assert _commands(page), f"{page.name} shows no command to run"


@pytest.mark.parametrize("page", TUTORIALS, ids=lambda page: page.stem)
def test_tutorial_runs_as_written(page, tmp_path, tmp_path_factory):
    """Each command of the page, in order, in a folder holding a copy of the example problems and
    robots (as a clone does): exit 0 and nothing written outside that folder. Python blocks run
    there too. The quick start's solve with -o is the suite's run of it
    (:func:`conftest.quick_start_solved`), written where -o says."""
    from conftest import quick_start_result

    for folder in ("problems", "robots"):
        shutil.copytree(REPO / folder, tmp_path / folder)
    for command in _commands(page):
        words = shlex.split(command)
        assert words[0] == "bcad", command
        if words[1:4] == ["solve", "problems/rx90_face_on_face.yaml", "-o"] and len(words) == 5:
            shutil.copyfile(quick_start_result(tmp_path_factory), tmp_path / words[4])
            continue
        run = run_bcad(*words[1:], cwd=tmp_path)
        assert run.returncode == 0, f"{command}\n{run.stderr[-3000:]}"
    for block in _blocks(page, "python"):
        run = subprocess.run([sys.executable, "-c", block], cwd=tmp_path, capture_output=True, text=True, timeout=600)
        assert run.returncode == 0, run.stderr[-3000:]


def test_generated_references_are_current():
    run = subprocess.run(
        [sys.executable, str(DOCS / "generate.py"), "--check"], capture_output=True, text=True, timeout=120
    )
    assert run.returncode == 0, run.stderr


def test_the_site_builds_with_warnings_as_errors(tmp_path):
    pytest.importorskip("sphinx")
    pytest.importorskip("myst_parser")
    run = subprocess.run(
        [sys.executable, "-m", "sphinx", "-W", "--keep-going", "-q", "-b", "html", str(DOCS), str(tmp_path / "html")],
        capture_output=True,
        text=True,
        timeout=300,
    )
    assert run.returncode == 0, run.stderr[-4000:]
    assert (tmp_path / "html" / "tutorials" / "kinematics_inversion.html").exists()


def test_the_readme_links_to_pages_that_exist():
    readme = (REPO / "README.md").read_text(encoding="utf-8")
    targets = re.findall(r"\]\((docs/[^)#]+)", readme)
    assert len(targets) > 20
    missing = [target for target in targets if not (REPO / target).exists()]
    assert not missing, missing


#: words about how bcad was made (its tracker, its sessions, its build machines), not what it does
HISTORY = re.compile(
    r"\bissues? #?\d|\bsandbox|previous build|earlier builds?|this ([\w-]+ )?machine|"
    r"this session|build machine|development machine",
    re.I,
)


def test_no_page_or_comment_speaks_of_history():
    files = [
        REPO / "README.md",
        *DOCS.rglob("*.md"),
        *DOCS.glob("*.py"),
        *(REPO / "bcad").rglob("*.py"),
        *(REPO / "bench").rglob("*.py"),
        *(REPO / "problems").rglob("*.yaml"),
        *(REPO / "problems").rglob("*.py"),
    ]
    found = []
    for path in files:
        for number, line in enumerate(path.read_text(encoding="utf-8").splitlines(), 1):
            if HISTORY.search(line):
                found.append(f"{path.relative_to(REPO)}:{number}: {line.strip()[:100]}")
    assert not found, "\n".join(found)


#: a citation of a numbered part of a paper: Eq. 2, Eqs. 6-9, Sect. 4.2.1, Table 2, Fig. 5
CITATION = re.compile(r"\b(?:Eqs?|Sect|Table|Fig)\. ?\d")


def test_a_page_that_cites_the_papers_says_where_their_equations_are():
    """bcad does not ship the papers: a page citing "Eq. 2" or "Sect. 4.2.1" links to the theory
    page, which writes the equations out and names the papers."""
    pages = [REPO / "README.md", *(page for page in DOCS.rglob("*.md") if "_build" not in page.parts)]
    unexplained = [
        str(page.relative_to(REPO))
        for page in pages
        if page.name != "theory.md"
        and CITATION.search(page.read_text(encoding="utf-8"))
        and "theory.md" not in page.read_text(encoding="utf-8")
    ]
    assert not unexplained, unexplained


def test_help_names_the_paper_of_every_citation():
    """Each line of a command's help that cites a numbered part of a paper names the paper."""
    import typer

    from bcad.cli import app

    root = typer.main.get_command(app)
    texts = [root.help or ""]
    for command in root.commands.values():
        texts.append(command.help or "")
        texts += [getattr(parameter, "help", None) or "" for parameter in command.params]
    unnamed = [
        text
        for text in texts
        for sentence in re.split(r"(?<=[.;:])\s+(?=[A-Z(])|\n\n", text)
        if CITATION.search(sentence) and not re.search(r"\b(?:19|20)\d\d paper|the paper's", sentence)
    ]
    assert not unnamed, unnamed


def test_the_language_guides_dh_robot_is_a_robot_that_reaches(tmp_path):
    """The planar 2R the language guide writes, its tool frame NAME/link_2 closing a cycle on a
    point at (1.2, 0.6): solve puts the tip there (an elbow of 1.0 and 0.8 m reaches it)."""
    import json

    import yaml

    (robots,) = [block for block in _blocks(DOCS / "guide" / "language.md", "yaml") if "dh: [{a: 1.0" in block]
    problem = yaml.safe_load(robots) | {
        "name": "dh-guide",
        "frames": ["world", "target"],
        "links": [
            {"name": "place", "parent": "world", "child": "target", "pose": [1.2, 0.6, 0, 0, 0, 0]},
            {
                "name": "reach",
                "parent": "target",
                "child": "arm/link_2",
                "close": True,
                "status": "LLFFFF",
                "distributions": {"tx": "normal(0, 0.01)", "ty": "normal(0, 0.01)"},
            },
        ],
        "solver": {"posterior_samples": 5000},
    }
    path = tmp_path / "dh.yaml"
    path.write_text(yaml.safe_dump(problem))
    run = run_bcad("solve", path, "--backend", "nominal", "--quiet")
    assert run.returncode == 0, run.stderr
    mean = json.loads(run.stdout)["posterior"]["links"]["reach"]["mean"]
    assert abs(mean[0]) < 1e-6 and abs(mean[1]) < 1e-6, mean
