"""The parameter vectors X, L and F of a compiled graph, with stable names.

Every parameter is named ``LINK.PARAM`` (``arm1/joint_2.rz``). X are the
unknowns (the optimisation dimension, Table 1), L the free parameters of the
tree links (the integration dimension: I(X) integrates over them, Eq. 2),
F the fixed ones. The L parameters of closing links are not integrated:
their value is computed from the cycle, and their distribution scores it
(the p_{O_i} of Eq. 2); they are listed as ``observed``.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from bcad.compiler.graph import KinematicGraph
from bcad.kinematics.chain import AffineParameter, LinkTransform, Term
from bcad.model.pose import PARAMETERS


@dataclass(frozen=True)
class Parameter:
    """One pose parameter of one link (link and slot -1: an entity's dimension,
    :mod:`bcad.compiler.dimensions`)."""

    name: str
    link: int
    slot: int  # 0..5 in (tx, ty, tz, rx, ry, rz)


@dataclass
class DistributionGroup:
    """A distribution and the parameters (columns of X, L or observed) it covers."""

    distribution: object
    columns: tuple[int, ...]


@dataclass
class ParameterTable:
    x: list[Parameter] = field(default_factory=list)
    x_bounds: list[tuple[float, float]] = field(default_factory=list)
    x_nominal: list[float] = field(default_factory=list)
    x_priors: list[DistributionGroup] = field(default_factory=list)
    l: list[Parameter] = field(default_factory=list)
    l_groups: list[DistributionGroup] = field(default_factory=list)
    f: list[Parameter] = field(default_factory=list)
    observed: list[Parameter] = field(default_factory=list)
    observed_groups: list[DistributionGroup] = field(default_factory=list)

    @property
    def x_names(self) -> list[str]:
        return [p.name for p in self.x]

    @property
    def l_names(self) -> list[str]:
        return [p.name for p in self.l]

    def not_normal(self) -> list[str]:
        """The L and scored parameters whose distribution is not a normal (nor a calibration's
        multivariate normal): the L's groups first, then the scores', each in its columns' order."""
        from bcad.model.distributions import MultivariateNormal, Normal

        return [
            parameters[column].name
            for groups, parameters in ((self.l_groups, self.l), (self.observed_groups, self.observed))
            for group in groups
            if not isinstance(group.distribution, (Normal, MultivariateNormal))
            for column in group.columns
        ]

    def sample_free_parameters(self, rng: np.random.Generator, n: int) -> np.ndarray:
        """N prior draws of the L deviations, shape (N, nL) (independent links, Sect. 4.1.2)."""
        values = np.zeros((n, len(self.l)))
        for group in self.l_groups:
            draw = group.distribution.sample(rng, n)
            values[:, list(group.columns)] = draw.reshape(n, len(group.columns))
        return values


def build_parameter_table(graph: KinematicGraph) -> tuple[ParameterTable, list[LinkTransform]]:
    """Name every parameter and express every tree link's pose as affine in X and L."""
    table = ParameterTable()
    closing = set(graph.closing_links)
    transforms: list[LinkTransform] = []
    for index, link in enumerate(graph.links):
        slots: list[AffineParameter] = []
        columns: dict[str, int] = {}
        if link.shared is not None and index not in closing:
            # A configuration's copy: its parameters are the shared link's, set below.
            transforms.append(
                LinkTransform(tuple(AffineParameter(float(v)) for v in link.nominal), link.origin, link.tip)
            )
            continue
        for slot, (parameter, letter) in enumerate(zip(PARAMETERS, link.status)):
            entry = Parameter(link.parameter_names.get(slot, f"{link.name}.{parameter}"), index, slot)
            nominal = float(link.nominal[slot])
            if index in closing:
                if letter == "L":
                    columns[parameter] = len(table.observed)
                    table.observed.append(entry)
                slots.append(AffineParameter(nominal))
            elif letter == "F":
                table.f.append(entry)
                slots.append(AffineParameter(nominal))
            elif letter == "L":
                columns[parameter] = len(table.l)
                table.l.append(entry)
                slots.append(AffineParameter(nominal, (Term("l", columns[parameter]),)))
            else:
                columns[parameter] = len(table.x)
                table.x.append(entry)
                table.x_bounds.append(link.bounds[parameter])
                table.x_nominal.append(nominal)
                slots.append(AffineParameter(0.0, (Term("x", columns[parameter]),)))
        for group, distribution in link.distributions.items():
            letter = link.status[PARAMETERS.index(group[0])]
            entry = DistributionGroup(distribution, tuple(columns[p] for p in group))
            if index in closing:
                table.observed_groups.append(entry)
            elif letter == "L":
                table.l_groups.append(entry)
            elif letter == "X":
                table.x_priors.append(entry)
        transforms.append(LinkTransform(tuple(slots), link.origin, link.tip))
    # Coupled parameters (URDF <mimic>): factor x the master's affine parameter + offset.
    by_name = {link.name: index for index, link in enumerate(graph.links)}
    for index, link in enumerate(graph.links):
        if not link.coupled:
            continue
        slots = list(transforms[index].parameters)
        for slot, (master, master_slot, factor, offset) in link.coupled.items():
            source = transforms[by_name[master]].parameters[master_slot]
            slots[slot] = AffineParameter(
                offset + factor * source.offset,
                tuple(Term(term.source, term.index, factor * term.coefficient) for term in source.terms),
            )
        transforms[index] = LinkTransform(tuple(slots), link.origin, link.tip)
    for index, link in enumerate(graph.links):
        if link.shared is not None and index not in closing:
            transforms[index] = LinkTransform(transforms[by_name[link.shared]].parameters, link.origin, link.tip)
    return table, transforms


def free_parameter_moments(compiled) -> tuple[np.ndarray, np.ndarray]:
    """Mean and variance of every L (deviation from nominal), from its distribution."""
    table = compiled.parameters
    mean, variance = np.zeros(len(table.l)), np.zeros(len(table.l))
    for group in table.l_groups:
        m, v = group.distribution.moments()
        mean[list(group.columns)], variance[list(group.columns)] = m, v
    return mean, variance
