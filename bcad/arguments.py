"""Checks of the arguments the commands and the Python API share, written once.

Each check is told how its caller spells the argument (:class:`Spelling`: ``--samples`` on the
command line, ``samples`` of ``bcad.solve`` in Python) and raises :class:`bcad.errors.InputError`
saying what was given and what was expected: the command line prints it and exits 2, the API
raises it.
"""

from __future__ import annotations

import math
import numbers
from pathlib import Path

from bcad.errors import InputError, refuse_nul, shown

#: the largest sample count any command or API call accepts
MAX_SAMPLES = 1_000_000_000
#: the largest seed (a seed is kept as a signed 64-bit integer)
MAX_SEED = 2**63 - 1
#: the smallest relative gap maxerror accepts (cells shrink towards double precision)
MIN_TOL = 1e-9


class Spelling:
    """How a caller names its arguments: the command line's options (``--samples``) or a Python
    function's keywords (``samples``, reported at ``bcad.maxerror``)."""

    def __init__(self, call: str | None = None):
        self.call = call  # the API function's name; None on the command line

    def name(self, argument: str) -> str:
        return f"--{argument.replace('_', '-')}" if self.call is None else argument

    def where(self, argument: str) -> str:
        """Where an error in ``argument`` is reported (a parser of the argument's text says it)."""
        return self.name(argument) if self.call is None else f"bcad.{self.call}: {argument}"

    def error(self, argument: str, value, expected: str) -> InputError:
        """``argument`` was given ``value``; ``expected`` says what it takes."""
        if self.call is None:
            text = shown(value)
            if isinstance(value, (int, float)) and not isinstance(value, bool) and text[:1] != "a":
                # a number quoted as a text option's value is ('-1', as '0'); not shown()'s words for
                # an integer too long to show ("an integer of about ... digits")
                text = shown(text)
            return InputError(self.name(argument), f"{text} is given; expected {expected}")
        return InputError(f"bcad.{self.call}", f"{argument} is {shown(value)}; expected {expected}")


COMMAND_LINE = Spelling()


def whole_number(value, argument: str, spelling: Spelling, low: int, high: int) -> int:
    """A whole number in [low, high]: an integer, a float without fraction (1e5) or, on the command
    line, text that reads as one ("2.5e6")."""
    number = value
    if isinstance(value, str) and spelling.call is None:
        try:
            number = float(value)
        except (ValueError, OverflowError):
            number = None
    if isinstance(number, float) and math.isfinite(number) and number.is_integer():
        number = int(number)
    if isinstance(number, bool) or not isinstance(number, numbers.Integral) or not low <= number <= high:
        raise spelling.error(argument, value, f"a whole number in [{_bound(low)}, {_bound(high)}]")
    return int(number)


def _bound(value: int) -> str:
    """A bound as a user would type it: 1e+09 where that is exact, every digit otherwise (a seed's
    2^63 - 1 is not 9.22337e+18)."""
    short = f"{value:g}"
    return short if float(short) == value else str(value)


def sample_count(value, argument: str, spelling: Spelling) -> int:
    """A number of samples: a whole number in [1, MAX_SAMPLES] (1e5 and, on the command line, "1e5")."""
    return whole_number(value, argument, spelling, 1, MAX_SAMPLES)


def random_seed(value, spelling: Spelling) -> int:
    """A seed: a whole number in [0, MAX_SEED] (the same seed gives the same numbers)."""
    return whole_number(value, "seed", spelling, 0, MAX_SEED)


def file_path(value, argument: str, spelling: Spelling) -> Path | None:
    """A file's path (text or :class:`pathlib.Path`, not empty), or None where none is given."""
    if value is None:
        return None
    if not isinstance(value, (str, Path)) or not str(value).strip():
        raise spelling.error(argument, value, "a file's path (str or pathlib.Path)")
    refuse_nul(value)
    return Path(value)


def choice(value, argument: str, spelling: Spelling, choices: tuple[str, ...]) -> str:
    """One of ``choices``."""
    if not isinstance(value, str) or value not in choices:
        raise spelling.error(argument, value, f"one of {', '.join(choices)}")
    return value


def relative_gap(value, argument: str, spelling: Spelling) -> float:
    """maxerror's tolerance: a relative gap in [MIN_TOL, 1) (doubles cannot certify a smaller one)."""
    if isinstance(value, bool) or not isinstance(value, (int, float)) or not MIN_TOL <= value < 1.0:
        raise spelling.error(argument, value, f"a relative gap in [{MIN_TOL:g}, 1)")
    return float(value)
