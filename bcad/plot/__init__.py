"""Pictures of problems and results: ``bcad plot``.

Every figure is drawn headless with matplotlib's Agg backend (the optional extra
``bcad[plot]``: matplotlib and corner; plotly too for ``.html``). Each drawing
function returns the figure and a record of what it drew (segment end points,
labels, curves), so that tests compare the picture with what it must show.
"""

from __future__ import annotations

from bcad.errors import InputError, install_hint

KINDS = ("arms", "posterior", "graph", "relaxation", "error", "residuals")


def require(module: str, where) -> object:
    """Import an optional plotting package, or say how to install it (exit 2)."""
    import importlib

    try:
        return importlib.import_module(module)
    except ImportError:
        raise InputError(where, f"bcad plot needs {module}: {install_hint('plot')}") from None


def pyplot(where):
    """matplotlib.pyplot on the Agg backend (no display), with SVG text kept as text."""
    matplotlib = require("matplotlib", where)
    matplotlib.use("Agg", force=True)
    matplotlib.rcParams["svg.fonttype"] = "none"
    matplotlib.rcParams["svg.hashsalt"] = "bcad"  # the same SVG for the same figure
    # Names are user text, drawn literally: '$x^{$' or '\\foo' is not mathtext to parse.
    matplotlib.rcParams["text.parse_math"] = False
    matplotlib.rcParams["text.usetex"] = False
    import matplotlib.pyplot as plt

    return plt
