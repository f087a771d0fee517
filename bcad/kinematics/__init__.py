"""Batched SE(3) evaluation of kinematic chains."""

from bcad.kinematics.chain import AffineParameter, BatchTransform, Chain, LinkTransform, Samples, Term

__all__ = ["AffineParameter", "BatchTransform", "Chain", "LinkTransform", "Samples", "Term"]
