"""Writing results: JSON, atomically, never over an input file, never over a device.

No output replaces a file the run has read (the problem, a robot's URDF or xacro
and what it includes, a measurement CSV, a calibration result, a mesh: see
:func:`record_input`), whatever link the output path reaches it by.

A regular file (or a new path) is written through a temporary file beside it
and a rename, so readers never see half a file. Anything else is written as
a shell's ``>`` would: a symbolic link is followed (its target is written,
the link stays), a device or FIFO (``-o /dev/stdout``, ``-o /dev/null``, a
named pipe) is written straight into, never replaced by a regular file.
"""

from __future__ import annotations

import json
import math
import os
import stat
from contextlib import contextmanager
from pathlib import Path

from bcad.errors import InputError


#: The inputs read inside each active :func:`recording_inputs` block, by identity
#: (device, inode): writers (bcad.io.check_output) refuse to replace any of them, through
#: whatever symbolic or hard link an output path reaches it by.
_RECORDERS: list[dict[tuple[int, int], Path]] = []


def record_input(path: Path | str, info=None) -> None:
    """Remember ``path`` as an input that no output of the running command may replace."""
    if not _RECORDERS:
        return
    try:
        info = info or os.stat(path)
    except OSError:
        return  # not there: nothing to protect
    for recorder in _RECORDERS:
        recorder.setdefault((info.st_dev, info.st_ino), Path(os.path.abspath(path)))


@contextmanager
def recording_inputs():
    """The inputs read inside the block, by identity: a command's (the ``bcad`` commands run
    in one) or a batch task's (whose result another process writes)."""
    recorded: dict[tuple[int, int], Path] = {}
    _RECORDERS.append(recorded)
    try:
        yield recorded
    finally:
        # by identity: list.remove compares by value, and two recorders may hold the same files
        del _RECORDERS[next(i for i, r in enumerate(_RECORDERS) if r is recorded)]


def input_read_as(path: Path | str) -> Path | None:
    """The input read by a running command that ``path`` is, through any link; None if none."""
    if not _RECORDERS:
        return None
    try:
        info = os.stat(path)
    except OSError:
        return None
    for recorder in _RECORDERS:
        if (info.st_dev, info.st_ino) in recorder:
            return recorder[(info.st_dev, info.st_ino)]
    return None


def json_text(document: dict) -> str:
    """Strict JSON (allow_nan=False): a figure that is not finite is written as null."""
    try:
        return json.dumps(document, indent=2, allow_nan=False) + "\n"
    except ValueError:  # a NaN or an infinity that a document let through: null, never invalid JSON
        return json.dumps(_finite_or_null(document), indent=2, allow_nan=False) + "\n"


def _finite_or_null(node):
    if isinstance(node, float):
        return node if math.isfinite(node) else None
    if isinstance(node, dict):
        return {key: _finite_or_null(value) for key, value in node.items()}
    if isinstance(node, (list, tuple)):
        return [_finite_or_null(value) for value in node]
    return node


def temporary_for(target: Path) -> Path:
    """The temporary file that an atomic write of ``target`` goes through: ``.NAME.PID.tmp``."""
    return target.with_name(f".{target.name}.{os.getpid()}.tmp")


def remove_stale_temporaries(folder: Path) -> None:
    """Delete the temporary files (``.NAME.PID.tmp``) that killed writers left in ``folder``;
    those of a writer still alive stay."""
    for temporary in folder.glob(".*.tmp"):
        parts = temporary.name.rsplit(".", 2)
        if len(parts) == 3 and parts[1].isdigit():
            try:
                os.kill(int(parts[1]), 0)
                continue  # its writer is alive
            except ProcessLookupError:
                pass
            except PermissionError:
                continue  # another user's live process
        temporary.unlink(missing_ok=True)


def _target(path: Path) -> Path:
    """The file that writing ``path`` writes: a symbolic link's final target."""
    return Path(os.path.realpath(path)) if path.is_symlink() else path


def check_output(path: Path, protected: list[Path] | None = None) -> None:
    """Refuse, before any work, an output that is an input file, a folder, or in a missing folder."""
    if str(path) == "":
        raise InputError(path, "empty output path")
    target = _target(path)
    for source in protected or []:
        if target.exists() and source.exists() and os.path.samefile(target, source):
            raise InputError(path, f"refusing to overwrite the input file {source} with a result; choose another output")
    # Any file this run has read (problem, URDF, xacro include, CSV, calibration, mesh),
    # reached through a symbolic or hard link or by its own name.
    source = input_read_as(target)
    if source is not None:
        raise InputError(path, f"refusing to overwrite the input file {source} with a result; choose another output")
    if target.is_dir():
        raise InputError(path, "is a folder; give a file name for the result")
    if not target.parent.is_dir():
        raise InputError(path, f"the folder {target.parent} does not exist")


def write_json_atomic(document: dict, path: Path, protected: Path | list[Path] | None = None) -> None:
    """Write the document to ``path`` (module docstring); never over a ``protected`` input file."""
    write_text_atomic(json_text(document), path, protected)


def write_text_atomic(text: str, path: Path, protected: Path | list[Path] | None = None) -> None:
    """Write ``text`` to ``path`` (module docstring); never over a ``protected`` input file."""
    write_bytes_atomic(text.encode("utf-8"), path, protected)


def write_bytes_atomic(data: bytes, path: Path, protected: Path | list[Path] | None = None) -> None:
    """Write ``data`` to ``path`` (module docstring); never over a ``protected`` input file."""
    if isinstance(protected, Path):
        protected = [protected]
    check_output(path, protected)
    target = _target(path)
    try:
        mode = os.stat(target).st_mode if target.exists() else None
    except OSError as exc:
        raise InputError(path, f"cannot write the result: {exc.strerror or exc}") from None
    if mode is not None and not stat.S_ISREG(mode):
        try:
            with open(target, "wb") as stream:
                stream.write(data)
        except OSError as exc:
            raise InputError(path, f"cannot write the result: {exc.strerror or exc}") from None
        return
    temporary = temporary_for(target)
    try:
        temporary.write_bytes(data)
        os.replace(temporary, target)
    except OSError as exc:
        try:
            temporary.unlink(missing_ok=True)
        except OSError:
            pass  # a read-only folder: nothing was created there either
        raise InputError(path, f"cannot write the result: {exc.strerror or exc}") from None
