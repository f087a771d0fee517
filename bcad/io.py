"""Writing results: JSON, atomically, never over an input file, never over a device.

No output replaces a file the run has read (the problem, a robot's URDF or xacro
and what it includes, a measurement CSV, a calibration result, a mesh: see
:func:`record_input`), whatever link the output path reaches it by.

A regular file, a new path or a symbolic link is written through a temporary
file beside it and a rename, so readers never see half a file: an output
replaces a link, never the file it points to (a link placed where a result
goes cannot make bcad rewrite a file elsewhere). A device or FIFO
(``-o /dev/stdout``, ``-o /dev/null``, a named pipe), or a link to one, is
written straight into, never replaced by a regular file; a named pipe that
no process opens for reading within 10 s is refused rather than waited on
for ever.

The temporary files are named ``.NAME.bcad-PID.tmp``; a batch removes those
that killed writers left of the files it writes, and nothing else.
"""

from __future__ import annotations

import errno
import glob
import json
import math
import os
import stat
from contextlib import contextmanager
from pathlib import Path

from bcad.errors import InputError, refuse_nul

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
    """The temporary file that an atomic write of ``target`` goes through: ``.NAME.bcad-PID.tmp``."""
    return target.with_name(f".{target.name}.bcad-{os.getpid()}.tmp")


def remove_stale_temporaries(folder: Path, names: list[str]) -> None:
    """Delete the temporary files that killed writers of the files ``names`` left in ``folder``
    (``.NAME.bcad-PID.tmp`` of no live process); a live writer's stay, and so does every other file."""
    for name in set(names):
        for temporary in folder.glob(f".{glob.escape(name)}.bcad-*.tmp"):
            pid = temporary.name[len(name) + len(".bcad-") + 1 : -len(".tmp")]
            if not pid.isdigit() or not temporary.is_file() or temporary.is_symlink():
                continue
            try:
                os.kill(int(pid), 0)
                continue  # its writer is alive
            except ProcessLookupError:
                pass
            except (PermissionError, OverflowError):
                continue  # another user's live process, or no process id at all
            temporary.unlink(missing_ok=True)


def _special(path: Path) -> bool:
    """Whether ``path`` (through links) is a device, FIFO or socket: written into, never replaced."""
    try:
        mode = os.stat(path).st_mode
    except OSError:
        return False  # new, or a dangling link: replaced
    return not stat.S_ISREG(mode) and not stat.S_ISDIR(mode)


def shortened_path(path: Path) -> str:
    """A path whose name is too long to show whole: its folder and the name's first 40 characters."""
    return str(path.with_name(path.name[:40] + "…"))


def check_output(path: Path, protected: list[Path] | None = None) -> None:
    """Refuse, before any work, an output that is an input file, a folder, or in a missing folder."""
    if str(path) == "":
        raise InputError(path, "empty output path")
    refuse_nul(path)
    if len(path.name) > 200:
        raise InputError(
            shortened_path(path),
            f"the file name has {len(path.name)} characters; at most 200 (the temporary file beside "
            "it adds a few to the file system's limit of 255)",
        )
    for source in protected or []:
        if path.exists() and source.exists() and os.path.samefile(path, source):
            raise InputError(
                path, f"refusing to overwrite the input file {source} with a result; choose another output"
            )
    # Any file this run has read (problem, URDF, xacro include, CSV, calibration, mesh),
    # reached through a symbolic or hard link or by its own name: the link would be replaced,
    # not the input, but a result named like an input is a slip worth stopping.
    source = input_read_as(path)
    if source is not None:
        raise InputError(path, f"refusing to overwrite the input file {source} with a result; choose another output")
    if path.is_dir():
        raise InputError(path, "is a folder; give a file name for the result")
    if not path.parent.is_dir():
        raise InputError(path, f"the folder {path.parent} does not exist")


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
    path = Path(path)
    check_output(path, protected)
    if _special(path):
        _write_into(data, path)
        return
    temporary = temporary_for(path)
    created = False
    try:
        # O_EXCL: never through a link or file someone placed at the temporary's name
        descriptor = os.open(temporary, os.O_WRONLY | os.O_CREAT | os.O_EXCL, 0o666)
        created = True
        with os.fdopen(descriptor, "wb") as stream:
            stream.write(data)
        os.replace(temporary, path)  # replaces a link itself, never its target
    except OSError as exc:
        if created:  # only what this write made: a file found at the temporary's name stays
            try:
                temporary.unlink()
            except OSError:
                pass
        raise InputError(path, f"cannot write the result: {exc.strerror or exc}") from None


#: seconds a named pipe may go without a reader before the write is refused
FIFO_READER_WAIT = 10.0


def _write_into(data: bytes, path: Path) -> None:
    """Write into a device or FIFO as a shell's ``>`` would; a FIFO that no process opens for
    reading within FIFO_READER_WAIT seconds is refused (a plain open would wait for ever)."""
    import time

    deadline = time.monotonic() + FIFO_READER_WAIT
    while True:
        try:
            descriptor = os.open(path, os.O_WRONLY | os.O_NONBLOCK)
            break
        except OSError as exc:
            if exc.errno != errno.ENXIO:
                raise InputError(path, f"cannot write the result: {exc.strerror or exc}") from None
            if time.monotonic() > deadline:
                raise InputError(
                    path, f"is a named pipe that no process read within {FIFO_READER_WAIT:g} s; start its reader first"
                ) from None
            time.sleep(0.05)
    try:
        os.set_blocking(descriptor, True)
        with os.fdopen(descriptor, "wb") as stream:
            stream.write(data)
    except OSError as exc:
        raise InputError(path, f"cannot write the result: {exc.strerror or exc}") from None
