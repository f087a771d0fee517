"""Sphinx configuration: the documentation is Markdown (MyST); the API reference comes from the
docstrings (autodoc with Napoleon's Google style); the CLI and language references are generated
files (``python docs/generate.py``) kept current by the tests."""

from __future__ import annotations

import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from bcad.version import __version__  # noqa: E402

project = "bcad"
author = "the bcad authors"
copyright = "2026, the bcad authors"
release = __version__
version = __version__

extensions = [
    "myst_parser",
    "sphinx.ext.autodoc",
    "sphinx.ext.napoleon",
    "sphinx.ext.mathjax",
]
source_suffix = {".md": "markdown"}
myst_enable_extensions = ["dollarmath", "colon_fence", "deflist"]
myst_heading_anchors = 4
exclude_patterns = ["_build", "pictures.py", "generate.py"]
autodoc_member_order = "bysource"
autodoc_typehints = "description"
napoleon_google_docstring = True
napoleon_numpy_docstring = False
html_theme = "furo"
html_title = f"bcad {__version__}"
html_static_path: list[str] = []
