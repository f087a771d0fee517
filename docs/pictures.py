"""Make the documentation's pictures (docs/*.png) by the commands its Pictures page shows.

    python docs/pictures.py            # rewrites the pictures in docs/
    python docs/pictures.py --out DIR  # writes them into DIR instead

The commands are read from docs/guide/pictures.md, so the pictures are always what the commands
shown there make; tests/plot/test_plot.py compares the committed copies with a fresh run.
"""

from __future__ import annotations

import argparse
import re
import shlex
import shutil
import subprocess
import sys
import tempfile
from pathlib import Path

REPO = Path(__file__).resolve().parent.parent


def readme_commands() -> list[list[str]]:
    """The Pictures page's commands, each as its words after ``bcad``."""
    page = (REPO / "docs" / "guide" / "pictures.md").read_text(encoding="utf-8")
    block = re.search(r"# Pictures: `bcad plot`.*?```\n(.*?)```", page, re.S).group(1)
    return [shlex.split(line)[1:] for line in block.splitlines() if line.strip()]


def make_pictures(out: Path, results: dict[str, Path] | None = None) -> list[Path]:
    """Run the commands with their results in a temporary folder and their pictures in ``out``.
    ``results``: results already made by the page's solve commands, by the name of the file each
    writes (``bayes.json``): those commands are not run again, their result is copied."""
    out.mkdir(parents=True, exist_ok=True)
    made = []
    with tempfile.TemporaryDirectory() as scratch:
        for words in readme_commands():
            if words[0] == "solve" and words[-2] == "-o" and words[-1] in (results or {}):
                shutil.copyfile(results[words[-1]], Path(scratch) / words[-1])
                continue
            placed = []
            for word in words:
                if word.startswith("docs/"):
                    placed.append(str(out / word.split("/", 1)[1]))
                    made.append(out / word.split("/", 1)[1])
                elif word.endswith(".json"):
                    placed.append(str(Path(scratch) / word))
                elif word.startswith("problems/"):
                    placed.append(str(REPO / word))
                else:
                    placed.append(word)
            run = subprocess.run([sys.executable, "-m", "bcad.cli", *placed], capture_output=True, text=True)
            if run.returncode not in (0, 3):
                raise SystemExit(f"bcad {' '.join(words)}: exit {run.returncode}\n{run.stderr}")
    return made


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--out", type=Path, default=REPO / "docs", help="folder for the pictures (default: docs/)")
    for path in make_pictures(parser.parse_args().out):
        print(f"wrote {path}")


if __name__ == "__main__":
    main()
