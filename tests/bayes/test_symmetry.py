"""Mirror-image configurations against the planar arm's integral by quadrature."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
from scipy.stats import norm, truncnorm

from bcad.bayes.model import BayesModel
from bcad.bayes.symmetry import mirror_image
from bcad.compiler import compile_problem
from bcad.model import load_problem

REPO = Path(__file__).resolve().parents[2]
PLANAR = (REPO / "problems" / "studies" / "planar_2r.yaml").read_text(encoding="utf-8")


def _integral(q, zero1) -> float:
    """I(X) of the planar arm by quadrature: the tool's distance from the line x = 1.2 m, scored
    by N(0, 5 mm), over the zero errors (the first with density ``zero1``, the second N(0, 0.05))."""
    d1 = np.linspace(-0.12, 0.12, 2401)
    d2 = np.linspace(-0.35, 0.35, 2401)
    a, b = np.meshgrid(d1, d2, indexing="ij")
    tx = np.cos(q[0] + a) + 0.8 * np.cos(q[0] + a + q[1] + b) - 1.2
    integrand = norm.pdf(tx, scale=0.005) * zero1(a) * norm.pdf(b, scale=0.05)
    return float(np.trapezoid(np.trapezoid(integrand, d2, axis=1), d1))


def _model(tmp_path, zero1: str) -> BayesModel:
    path = tmp_path / "planar.yaml"
    path.write_text(PLANAR.replace("'normal(0, 0.02)'", f"'{zero1}'"), encoding="utf-8")
    return BayesModel(compile_problem(load_problem(path)))


def test_a_mirror_image_is_recognised_where_the_integral_is_equal(tmp_path):
    model = _model(tmp_path, "normal(0, 0.02)")
    a, b = np.array([0.3, 1.1]), np.array([-0.3, -1.1])  # reflected about the x axis
    density = norm(scale=0.02).pdf
    assert np.isclose(_integral(a, density), _integral(b, density), rtol=1e-9)
    assert mirror_image(model, a, b) and mirror_image(model, b, a)
    # another configuration of a different value is not
    other = np.array([0.5, 0.8])
    assert not np.isclose(_integral(a, density), _integral(other, density), rtol=1e-3)
    assert not mirror_image(model, a, other)


def test_polished_finalists_keep_one_of_each_mirror_pair(tmp_path):
    from bcad.bayes.estimators import not_mirror_images

    model = _model(tmp_path, "normal(0, 0.02)")
    points = np.array([[0.3, 1.1], [0.5, 0.8], [-0.3, -1.1], [-0.5, -0.8], [0.9, 0.2]])
    assert not_mirror_images(model, points) == [0, 1, 4]


def test_no_mirror_image_where_the_reflected_error_is_not_symmetric(tmp_path):
    # The first zero error skewed (a normal truncated to [-0.02, 0.06], centred so that its mean
    # is 0: the configurations are linearised at the same point, and only the distribution's
    # asymmetry tells them apart): the two configurations' integrals differ.
    centre = -0.010335805386366066
    density = truncnorm((-0.02 - centre) / 0.02, (0.06 - centre) / 0.02, loc=centre, scale=0.02)
    assert abs(density.mean()) < 1e-12
    model = _model(tmp_path, f"truncnormal({centre!r}, 0.02, -0.02, 0.06)")
    a, b = np.array([0.3, 1.1]), np.array([-0.3, -1.1])
    assert not np.isclose(_integral(a, density.pdf), _integral(b, density.pdf), rtol=1e-2)
    assert not mirror_image(model, a, b)


def test_the_planar_solve_sets_its_mirror_image_aside(tmp_path):
    from conftest import run_bcad

    output = tmp_path / "planar.json"
    run = run_bcad("solve", str(REPO / "problems" / "studies" / "planar_2r.yaml"), "-o", str(output), cwd=REPO)
    assert run.returncode == 0, run.stderr
    search = json.loads(output.read_text())["diagnostics"]["search"]
    assert search["choice"]["mirror_images"] == 1
    assert "1 mirror image of the finalists set aside" in run.stdout + run.stderr
    # no two finalists are mirror images (q and -q) of one another
    finalists = [np.array(list(b["polished"].values())) for b in search["basins"] if "polished" in b]
    for k, x in enumerate(finalists):
        assert all(np.abs(x + y).max() > 1e-2 for y in finalists[k + 1 :])
