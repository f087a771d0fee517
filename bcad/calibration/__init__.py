"""Calibration: identify a cell's free parameters from measurements."""
