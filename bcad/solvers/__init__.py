"""Solver backends, one module per backend."""
