"""The one error type a user's input can raise, and how it is printed."""

from __future__ import annotations

import re
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


#: why a path with a NUL character names no file
NUL_IN_PATH = "has a NUL character (\\x00), which no file name holds"


def refuse_nul(path) -> None:
    """An :class:`InputError` for a path with a NUL character, which no file name holds (the
    operating system's calls refuse it with a ValueError; the command line cannot pass one, a
    Python caller or a problem given as a mapping can)."""
    if "\x00" in str(path):
        raise InputError(printable(str(path)), f"the path {NUL_IN_PATH}")


def install_hint(extra: str) -> str:
    """How to install one of bcad's optional extras, from a release and from a clone."""
    return f"pip install 'bcad[{extra}]' (in a clone of bcad: pip install -e '.[{extra}]')"


def quoted(text: object, limit: int = 24) -> str:
    """``text`` quoted for a message, cut to ``limit`` characters: a cell or a name of a file of
    the expected kind is shown so that the user finds it, never more of the file than that."""
    text = str(text)
    return repr(text[:limit] + "…") if len(text) > limit else repr(text)


def listed(names, limit: int = 8) -> str:
    """Names for a message, the first ``limit`` of them and how many more: a problem of thousands
    of joints lists a few of them, not a page."""
    names = [str(name) for name in names]
    return ", ".join(names[:limit]) + (f" and {len(names) - limit} more" if len(names) > limit else "")


def counted(count: int, one: str, many: str | None = None) -> str:
    """``count`` and the noun, singular for one: "1 climb", "73 climbs", "1 distinct maximum"."""
    return f"{count} {one if count == 1 else many or one + 's'}"


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


#: ASCII's control characters, and those but tab and newline
_ASCII_CONTROL = re.compile(r"[\x00-\x1f\x7f]")
_ASCII_CONTROL_BUT_LINES = re.compile(r"[\x00-\x08\x0b-\x1f\x7f]")
#: Unicode's characters a terminal acts on rather than shows, beyond ASCII: C1's controls, the
#: bidirectional controls (a right-to-left override reorders what follows it), the invisible
#: zero-width space and word joiner, the byte order mark, line and paragraph separators, and
#: surrogates. Other format characters are shown as text is meant to read (the zero-width joiner
#: of an emoji sequence or of an Indic name, a soft hyphen, an emoji flag's tag characters).
_UNICODE_ACTED_ON = re.compile("[\x80-\x9f\u061c\u200b\u200e\u200f\u2028-\u202e\u2060\u2066-\u2069\ufeff\ud800-\udfff]")


def unprintable(text: str, lines: bool = False) -> str | None:
    """The first character of ``text`` that a terminal would act on rather than show (an escape
    sequence's ESC, a carriage return, a right-to-left override), or None. ``lines``: tab and
    newline are text (a description's lines); otherwise they are acted on too (a name printed on
    one line of a table or message would start a line of its own)."""
    control = _ASCII_CONTROL_BUT_LINES if lines else _ASCII_CONTROL
    if text.isascii():
        found = control.search(text)
    else:
        found = min(
            (match for match in (control.search(text), _UNICODE_ACTED_ON.search(text)) if match),
            key=lambda match: match.start(),
            default=None,
        )
    return found.group() if found else None


def printable(text: str) -> str:
    """``text`` on one line, each character :func:`unprintable` finds written as its escape
    (``\\x1b``, ``\\x0a`` for a newline, ``\\u202e``): a name or message from a file is shown,
    never acted on by the terminal, and never starts a line of its own."""
    if unprintable(text) is None:
        return text
    return _UNICODE_ACTED_ON.sub(_escape, _ASCII_CONTROL.sub(_escape, text))


def _escape(match: re.Match) -> str:
    """A character as Python writes its escape: \\x1b, \\u202e."""
    code = ord(match.group())
    return f"\\x{code:02x}" if code < 0x100 else f"\\u{code:04x}"


def acted_on(character: str) -> str:
    """What an input error says of a character :func:`unprintable` found."""
    return f"holds the character U+{ord(character):04X}, which a terminal acts on rather than shows"
