"""Numerics shared by the families below them: seeded random streams, importance weights
and their diagnostics, streamed sums, bounded least squares."""
