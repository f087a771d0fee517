"""The one error type a user's input can raise, and how it is printed."""

from __future__ import annotations

import re
import unicodedata
from dataclasses import dataclass
from pathlib import Path


@dataclass
class InputError(Exception):
    """Invalid user input: printed as ``FILE:LINE:COL: message`` and exit code 2.

    ``line`` and ``column`` are 1-based and ``None`` where the input gives none
    (a missing file, say).
    """

    file: Path | str
    message: str
    line: int | None = None
    column: int | None = None

    def __str__(self) -> str:
        where = str(self.file)
        if self.line is not None:
            where += f":{self.line}"
            if self.column is not None:
                where += f":{self.column}"
        return f"{where}: {self.message}"


def install_hint(extra: str) -> str:
    """How to install one of bcad's optional extras, from a release and from a clone."""
    return f"pip install 'bcad[{extra}]' (in a clone of bcad: pip install -e '.[{extra}]')"


def quoted(text: object, limit: int = 24) -> str:
    """``text`` quoted for a message, cut to ``limit`` characters: a cell or a name of a file of
    the expected kind is shown so that the user finds it, never more of the file than that."""
    text = str(text)
    return repr(text[:limit] + "…") if len(text) > limit else repr(text)


def shown(value: object, limit: int = 60) -> str:
    """A Python value as a message shows it: its repr cut to ``limit`` characters; an integer too
    long for Python to turn into digits (over 4300 of them) by its size alone."""
    if isinstance(value, int) and value.bit_length() > 10_000:
        return f"an integer of about {int(value.bit_length() * 0.30103):,} digits"
    try:
        text = repr(value)
    except (ValueError, RecursionError):  # a huge integer or a deep structure inside a container
        return f"a {type(value).__name__} too large to show"
    return text[:limit]


#: ASCII's control characters but tab and newline
_ASCII_CONTROL = re.compile(r"[\x00-\x08\x0b-\x1f\x7f]")
#: Unicode's categories a terminal acts on rather than shows: controls (C1's included), format
#: characters (a right-to-left override, zero-width marks), line and paragraph separators, and
#: surrogates
UNPRINTABLE_CATEGORIES = frozenset({"Cc", "Cf", "Zl", "Zp", "Cs"})


def _unprintable_character(character: str) -> bool:
    if character < "\x80":
        return _ASCII_CONTROL.match(character) is not None
    return unicodedata.category(character) in UNPRINTABLE_CATEGORIES


def unprintable(text: str) -> str | None:
    """The first character of ``text`` that a terminal would act on rather than show (an escape
    sequence's ESC, a carriage return, a right-to-left override), or None: tab and newline
    are printable."""
    if text.isascii() and _ASCII_CONTROL.search(text) is None:
        return None
    return next((character for character in text if _unprintable_character(character)), None)


def printable(text: str) -> str:
    """``text`` with each character :func:`unprintable` finds written as its escape (``\\x1b``,
    ``\\u202e``): a name or message from a file is shown, never acted on by the terminal."""
    if unprintable(text) is None:
        return text
    return "".join(_escape(character) if _unprintable_character(character) else character for character in text)


def _escape(character: str) -> str:
    """A character as Python writes its escape: \\x1b, \\u202e, \\U000e0001."""
    code = ord(character)
    return f"\\x{code:02x}" if code < 0x100 else f"\\u{code:04x}" if code < 0x10000 else f"\\U{code:08x}"
