"""A serial chain's first-order clearance error map, with certified enclosures.

Conventions of Berger et al. (2010), kept exactly:

* S_j takes frame F_j onto F_{j+1} (Eq. 1-2), P = S_1 ... S_n (Eq. 3).
* Joint j's error screw ds_j = [dr; dt] is expressed in F_j and applied
  before S_j: P' = prod_j exp(dS_j) S_j (Eq. 10).
* To first order, dp = [dp_r; dp_t] = sum_j Ad(G_j^-1) ds_j with
  G_j = S_j ... S_n = (R_j, p_j) (Eq. 11), expressed in F_{n+1}:

      dp_r = sum_j R_j^T dr_j
      dp_t = sum_j R_j^T (dt_j + dr_j x p_j)

For a direction u the transposed map gives, per joint, R_j u (paired with
dr_j in the rotation problem, with dt_j in the translation problem) and
p_j x (R_j u) = [p_j]x R_j u (paired with dr_j in the translation problem).
``M_j = [R_j; [p_j]x R_j]`` (6 x 3) holds both; it is computed in arb ball
arithmetic (python-flint) from the chain's doubles, so its interval
enclosure contains the exact matrix despite the trigonometric functions and
products, and then handed to numpy as [lo, hi] arrays.

**The clearance variables.** The sets of Eq. 6-9 are discs and intervals of
per-joint variables. For a chain with relative angles (the paper's) they are
the error screws themselves. A planar chain may declare ``angles: absolute``:
joint j's rot_z clearance then bounds x_j, the turn of link j from the base
(each link driven from the base), and the screw's dr_z is x_j - x_{j-1}. The
variables stay a product of discs and intervals; the map is linear, so two
more rows of M carry x_j's first-order coefficients: row 6 (rotation) is
row 2 of M_j less row 2 of M_{j+1}, row 7 (translation) likewise of row 5
(for relative angles, rows 2 and 5 as they are). Everything that maximises
over the clearance set works on the variables; the exact model maps them to
screws (:meth:`ErrorMap.relative_screws`) and its constants use the bounds of
the screws (:attr:`ErrorMap.screw_clearance`: |dr_z| <= c_j + c_{j-1}).
"""

from __future__ import annotations

from dataclasses import dataclass
from functools import cached_property

import numpy as np

from bcad.compiler.units import angle_scale, urdf_length_scale
from bcad.errors import InputError, counted
from bcad.model.clearance import ChainProblem, DhChain
from bcad.worstcase.intervals import Interval, down, up


@dataclass
class ErrorMap:
    """Everything the maximisation needs about one chain at one configuration."""

    S: np.ndarray  # (n, 4, 4) float S_j
    M: Interval  # (n, 8, 3) enclosure of [R_j; [p_j]x R_j] and the rz variable's rows (module docstring)
    M_float: np.ndarray  # (n, 8, 3) its midpoint
    clearance: np.ndarray  # (n, 4): rot_xy, rot_z, trans_xy, trans_z (internal units) of the variables
    absolute: bool = False  # rot_z bounds each link's turn from the base (module docstring)

    @property
    def joints(self) -> int:
        return self.S.shape[0]

    @cached_property
    def adjoints(self) -> np.ndarray:
        """Ad(G_j^-1) (n, 6, 6): [R_j^T 0; ([p_j]x R_j)^T R_j^T] from M_j = [R_j; [p_j]x R_j],
        which maps joint j's error screw to the end frame (Eq. 11's terms)."""
        rotation, arm = np.swapaxes(self.M_float[:, 0:3], 1, 2), np.swapaxes(self.M_float[:, 3:6], 1, 2)
        adjoints = np.zeros((self.joints, 6, 6))
        adjoints[:, :3, :3] = adjoints[:, 3:, 3:] = rotation
        adjoints[:, 3:, :3] = arm
        return adjoints

    @property
    def nominal(self) -> np.ndarray:
        """P = S_1 ... S_n (Eq. 3), in floating point: the chain without clearance."""
        P = np.eye(4)
        for S in self.S:
            P = P @ S
        return P

    @property
    def screw_clearance(self) -> np.ndarray:
        """(n, 4) bounds of the error screws' parts: the clearances, with |dr_z| <= c_j + c_{j-1}
        for absolute angles (rounded up)."""
        if not self.absolute:
            return self.clearance
        bounds = self.clearance.copy()
        total = bounds[1:, 1] + self.clearance[:-1, 1]
        bounds[1:, 1] = np.where(total > 0, up(total), 0.0)
        return bounds

    def relative_screws(self, variables: np.ndarray) -> np.ndarray:
        """The error screws (..., n, 6) of clearance variables (..., n, 6): themselves, or for
        absolute angles with dr_z = x_j - x_{j-1}."""
        if not self.absolute:
            return variables
        screws = variables.copy()
        screws[..., 1:, 2] = variables[..., 1:, 2] - variables[..., :-1, 2]
        return screws


def _arb_rotation(axis: int, angle):
    import flint

    c, s = angle.cos(), angle.sin()
    i, j = (axis + 1) % 3, (axis + 2) % 3
    rows = [[flint.arb(0)] * 3 for _ in range(3)]
    rows[axis][axis] = flint.arb(1)
    rows[i][i], rows[j][j], rows[j][i], rows[i][j] = c, c, s, -s
    return flint.arb_mat(rows)


def _arb_transform(rotation, translation):
    import flint

    rows = [[rotation[r, c] for c in range(3)] + [translation[r]] for r in range(3)]
    rows.append([flint.arb(0), flint.arb(0), flint.arb(0), flint.arb(1)])
    return flint.arb_mat(rows)


def _axis_alignment(axis: int, sign: int):
    """The exact rotation (entries 0 and +-1) whose z column is sign x e_axis, as a transform."""
    import flint

    z = [0, 0, 0]
    z[axis] = sign
    # A right-handed frame: x and y complete z (a cyclic permutation, signs fixed by z's).
    x = [0, 0, 0]
    x[(axis + 1) % 3] = 1
    y = [z[1] * x[2] - z[2] * x[1], z[2] * x[0] - z[0] * x[2], z[0] * x[1] - z[1] * x[0]]
    rows = [[flint.arb(x[r]), flint.arb(y[r]), flint.arb(z[r])] for r in range(3)]
    return _arb_transform(flint.arb_mat(rows), [flint.arb(0)] * 3)


def _identity():
    import flint

    return flint.arb_mat([[1 if r == c else 0 for c in range(4)] for r in range(4)])


def _rigid_inverse(T):
    """[R t; 0 1]^-1 = [R^T -R^T t; 0 1], exactly as balls (no general matrix inversion)."""
    rotation = [[T[c, r] for c in range(3)] for r in range(3)]
    translation = [-(rotation[r][0] * T[0, 3] + rotation[r][1] * T[1, 3] + rotation[r][2] * T[2, 3]) for r in range(3)]
    import flint

    return _arb_transform(flint.arb_mat(rotation), translation)


def _dh_transform(a: float, alpha: float, d: float, theta: float):
    """Eq. 2 of the 2010 paper: S = Rz(theta) Tz(d) Tx(a) Rx(alpha)."""
    import flint

    theta, alpha = flint.arb(theta), flint.arb(alpha)
    ct, st, ca, sa = theta.cos(), theta.sin(), alpha.cos(), alpha.sin()
    a, d, zero, one = flint.arb(a), flint.arb(d), flint.arb(0), flint.arb(1)
    return flint.arb_mat(
        [
            [ct, -st * ca, st * sa, a * ct],
            [st, ct * ca, -ct * sa, a * st],
            [zero, sa, ca, d],
            [zero, zero, zero, one],
        ]
    )


def _origin_transform(xyz, rpy, length: float):
    import flint

    rotation = (
        _arb_rotation(2, flint.arb(rpy[2])) * _arb_rotation(1, flint.arb(rpy[1])) * _arb_rotation(0, flint.arb(rpy[0]))
    )
    # The URDF's metres times the unit factor, as an exact ball product.
    translation = [flint.arb(v) * flint.arb(length) for v in xyz]
    return _arb_transform(rotation, translation)


def _urdf_screws(problem: ChainProblem) -> list:
    """S_j of a URDF chain at configuration q: F_j is joint j's frame before its rotation."""
    import flint

    from bcad.compiler.urdf import read_urdf  # lxml: only URDF chains need it

    doc, chain = problem.source, problem.chain
    path = doc.named_file(("chain", "urdf"), chain.urdf, "a URDF file", "URDF file ")
    urdf = read_urdf(path)
    by_child = {joint.child: joint for joint in urdf.joints}
    actuated = [joint for joint in urdf.joints if joint.type != "fixed"]
    tip = chain.tip or (actuated[-1].child if actuated else None)
    if tip not in urdf.links:
        raise doc.error(("chain", "tip"), f"URDF '{path.name}' has no link '{tip}'")
    path_joints = []
    link, visited = tip, set()
    while link in by_child:
        if link in visited:  # a malformed URDF whose joints form a cycle
            raise doc.error(("chain", "urdf"), f"URDF '{path.name}': its joints form a cycle through link '{link}'")
        visited.add(link)
        path_joints.append(by_child[link])
        link = by_child[link].parent
    path_joints.reverse()
    moving = [joint for joint in path_joints if joint.type != "fixed"]
    # A <mimic> joint is a clearance joint whose angle follows its master's (q = multiplier
    # q_master + offset): q gives the joints that mimic none, as solve's X do.
    commanded = [joint for joint in moving if joint.mimic is None]
    followers = [joint for joint in moving if joint.mimic is not None]
    if len(chain.q) != len(commanded):
        names = ", ".join(repr(j.name) for j in followers)
        verb = "follows" if len(followers) == 1 else "follow"
        following = f" that mimic none ({names} {verb} another joint by <mimic>)" if followers else ""
        raise doc.error(
            ("chain", "q"),
            f"q has {len(chain.q)} values but the chain to '{tip}' has {len(commanded)} actuated joints{following}",
        )
    length, angle = urdf_length_scale(problem.units), angle_scale(problem.units)
    # each actuated joint's angle, rad: q's, then each mimic's from its master's on the chain (a
    # master anywhere on it, a mimic of a mimic too; as many passes as mimics at most)
    angles = {joint.name: flint.arb(value) * flint.arb(angle) for joint, value in zip(commanded, chain.q)}
    for _ in range(len(followers)):
        for joint in followers:
            master, multiplier, offset = joint.mimic
            if joint.name not in angles and master in angles:
                angles[joint.name] = flint.arb(multiplier) * angles[master] + flint.arb(offset)
    for joint in followers:
        if joint.name not in angles:
            raise InputError(
                path,
                f"joint '{joint.mimic[0]}', which joint '{joint.name}' mimics, is no actuated joint on the chain to "
                f"'{tip}'; expected a master whose angle q gives",
                joint.line,
                joint.column,
            )
    transform = _identity()
    frames = []
    for joint in path_joints:
        transform = transform * _origin_transform(joint.xyz, joint.rpy, length)
        if joint.type == "fixed":
            continue
        axis = int(np.argmax(np.abs(joint.axis)))
        if joint.type not in ("revolute", "continuous") or abs(abs(joint.axis[axis]) - 1.0) > 1e-12:
            raise InputError(
                path,
                f"joint '{joint.name}' must be revolute about its x, y or z axis to be a clearance joint F_j",
                joint.line,
                joint.column,
            )
        # F_j has its z along the joint's axis (Sect. 2 of the 2010 paper): for an axis along
        # +-x or +-y the joint frame's axes are permuted exactly so that z lies there (_axis_alignment).
        align = _axis_alignment(axis, int(np.sign(joint.axis[axis])))
        frames.append(transform * align)
        q = angles[joint.name]
        transform = transform * align * _arb_transform(_arb_rotation(2, q), [flint.arb(0)] * 3) * _rigid_inverse(align)
    frames.append(transform)
    return [_rigid_inverse(frames[j]) * frames[j + 1] for j in range(len(moving))]


def _clearances(problem: ChainProblem, joints: int) -> np.ndarray:
    clearance = problem.clearance
    if isinstance(clearance, list):
        if len(clearance) != joints:
            raise problem.source.error(
                ("clearance",), f"clearance lists {counted(len(clearance), 'joint')} but the chain has {joints}"
            )
        rows = clearance
    else:
        rows = [clearance] * joints
    angle = angle_scale(problem.units)
    return np.array([[c.rot_xy * angle, c.rot_z * angle, c.trans_xy, c.trans_z] for c in rows], dtype=float)


def _to_interval(value) -> tuple[float, float]:
    # float() rounds to nearest; one more ulp outward keeps the enclosure.
    return float(down(float(value.lower()))), float(up(float(value.upper())))


def build_error_map(problem: ChainProblem) -> ErrorMap:
    """S_j, and the certified enclosure of M_j = [R_j; [p_j]x R_j] for every joint."""
    import flint

    if isinstance(problem.chain, DhChain):
        angle = angle_scale(problem.units)
        screws = [_dh_transform(r.a, r.alpha * angle, r.d, r.theta * angle) for r in problem.chain.dh]
    else:
        screws = _urdf_screws(problem)
    n = len(screws)
    if n == 0:
        raise problem.source.error(("chain",), "the chain has no joint")
    clearance = _clearances(problem, n)

    lo, hi = np.zeros((n, 6, 3)), np.zeros((n, 6, 3))
    G = _identity()
    for j in range(n - 1, -1, -1):
        G = screws[j] * G  # G_j = S_j ... S_n
        R = flint.arb_mat([[G[r, c] for c in range(3)] for r in range(3)])
        p = [G[0, 3], G[1, 3], G[2, 3]]
        skew = flint.arb_mat([[0, -p[2], p[1]], [p[2], 0, -p[0]], [-p[1], p[0], 0]])
        pR = skew * R
        for r in range(3):
            for c in range(3):
                lo[j, r, c], hi[j, r, c] = _to_interval(R[r, c])
                lo[j, r + 3, c], hi[j, r + 3, c] = _to_interval(pR[r, c])
    absolute = isinstance(problem.chain, DhChain) and problem.chain.angles == "absolute"
    lo, hi = _variable_rows(lo, hi, absolute)
    S = np.array([[[float(screw[r, c].mid()) for c in range(4)] for r in range(4)] for screw in screws])
    return ErrorMap(S, Interval(lo, hi), 0.5 * (lo + hi), clearance, absolute)


def _variable_rows(lo: np.ndarray, hi: np.ndarray, absolute: bool) -> tuple[np.ndarray, np.ndarray]:
    """M's rows 6 and 7, the rz variable's coefficients (module docstring), appended outward-rounded."""
    lo_rows, hi_rows = lo[:, [2, 5], :].copy(), hi[:, [2, 5], :].copy()
    if absolute:
        # x_j enters dr_z of joint j with +1 and of joint j + 1 with -1
        lo_rows[:-1] = down(lo_rows[:-1] - hi[1:, [2, 5], :])
        hi_rows[:-1] = up(hi_rows[:-1] - lo[1:, [2, 5], :])
    return np.concatenate([lo, lo_rows], axis=1), np.concatenate([hi, hi_rows], axis=1)


__all__ = ["ErrorMap", "build_error_map"]
