"""Process-wide settings that make batched numpy code fast.

Batched kinematics creates many short-lived arrays of N doubles. With glibc's
defaults every array above 128 KiB is a fresh ``mmap``, so each one pays page
faults on first touch; keeping freed blocks in the heap instead makes the
RX90 closing-pose evaluation about 1.5x faster (see ``bench/kinematics.py``).
Called by the command line and the benchmarks, never on library import.
"""

from __future__ import annotations

import ctypes
import ctypes.util
import sys

_M_TRIM_THRESHOLD = -1
_M_MMAP_THRESHOLD = -3
_tuned = False


def tune_allocator() -> bool:
    """Keep large freed blocks in glibc's heap. Returns whether it applied."""
    global _tuned
    if _tuned:
        return True
    if not sys.platform.startswith("linux"):
        return False
    try:
        libc = ctypes.CDLL(ctypes.util.find_library("c") or "libc.so.6")
        ok = libc.mallopt(_M_MMAP_THRESHOLD, 1 << 30) and libc.mallopt(_M_TRIM_THRESHOLD, 1 << 31)
    except (OSError, AttributeError):
        return False
    _tuned = bool(ok)
    return _tuned
