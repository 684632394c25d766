"""Output paths checked before any work starts (the CLI's ``--html``, ``--db``, ...).

A run of minutes must not end in an ``OSError`` traceback because its output
path is a directory, lies in a missing or read-only place, or has a name the
file system refuses. :func:`check_output` finds that out first, without
creating anything, and raises ``ValueError`` naming the option, what was
expected and what was got.
"""

from __future__ import annotations

import os
import stat
import tempfile
from pathlib import Path

from handle_drake.scenario_checks import short_path

__all__ = ["OUTPUT_OPTIONS", "check_output", "check_outputs"]

#: argparse destination -> (option, "file" or "dir") of every output the CLI writes.
OUTPUT_OPTIONS = {
    "html": ("--html", "file"),
    "save_scenario": ("--save-scenario", "file"),
    "db": ("--db", "file"),
    "out": ("--out", "dir"),
    "plot": ("--plot", "file"),
    "json": ("--json", "file"),  # a file path (instruments); perceive's --json is a flag
    "save_frames": ("--save-frames", "dir"),
    "write_scenarios": ("--write-scenarios", "dir"),
    "directory": ("DIRECTORY", "dir"),  # midi write-scenarios
}


def _limit(path: Path, name: str, default: int) -> int:
    try:
        return os.pathconf(path, name)
    except (OSError, ValueError):
        return default


def check_output(option: str, path, kind: str = "file") -> Path:
    """``path`` if a ``kind`` ("file" or "dir") can be written there; ValueError otherwise."""
    if not isinstance(path, (str, os.PathLike)) or not str(path):
        raise ValueError(f"{option}: expected a path, got {path!r}")
    path = Path(path)
    shown = short_path(path)
    if "\0" in str(path):
        raise ValueError(f"{option}: expected a path without NUL bytes, got {shown!r}")
    try:
        exists = path.exists()
        ancestor = path.absolute().parent
        while not ancestor.exists():
            ancestor = ancestor.parent
    except OSError as error:  # e.g. a name longer than the file system allows
        raise ValueError(f"{option}: {error.strerror}: {shown}") from None
    if exists:
        if kind == "file" and path.is_dir():
            raise ValueError(f"{option}: expected a file path, got the directory {shown}")
        if kind == "dir" and not path.is_dir():
            raise ValueError(f"{option}: expected a directory, got the file {shown}")
        if not os.access(path, os.W_OK):
            raise ValueError(f"{option}: {shown} is read-only")
        if kind == "dir":
            _try_create(option, path, shown)
        else:
            _try_open(option, path, shown)
        return path
    if not ancestor.is_dir():
        raise ValueError(f"{option}: expected a path under a directory, but {short_path(ancestor)} "
                         f"is a file")
    if not os.access(ancestor, os.W_OK | os.X_OK):
        raise ValueError(f"{option}: cannot create {shown}: {short_path(ancestor)} is read-only")
    _try_create(option, ancestor, shown)
    name_max = _limit(ancestor, "PC_NAME_MAX", 255)
    for part in path.parts:
        if len(os.fsencode(part)) > name_max:
            raise ValueError(f"{option}: expected file names of at most {name_max} bytes, got "
                             f"one of {len(os.fsencode(part))} ({part[:40]}...)")
    path_max = _limit(ancestor, "PC_PATH_MAX", 4096)
    if len(os.fsencode(str(path.absolute()))) >= path_max:
        raise ValueError(f"{option}: expected a path shorter than {path_max} bytes, got {shown}")
    return path


def _try_create(option: str, directory: Path, shown: str) -> None:
    """Creates and at once removes a nameless file in ``directory``: what the OS
    says, not what the permission bits say (root passes ``os.access`` on /proc,
    a read-only mount, a full disk's quota...)."""
    try:
        with tempfile.TemporaryFile(dir=directory):
            pass
    except OSError as error:
        raise ValueError(f"{option}: cannot create {shown}: {short_path(directory)}: "
                         f"{error.strerror or error}") from None


def _try_open(option: str, path: Path, shown: str) -> None:
    """Opens the existing ``path`` for appending (and closes it): nothing is
    written, its contents and times stay as they are."""
    mode = path.stat().st_mode
    if stat.S_ISFIFO(mode) or stat.S_ISSOCK(mode):
        raise ValueError(f"{option}: expected a regular file, got a FIFO or socket {shown}")
    try:
        os.close(os.open(path, os.O_WRONLY | os.O_APPEND | os.O_NONBLOCK))
    except OSError as error:
        raise ValueError(f"{option}: cannot write {shown}: {error.strerror or error}") from None


def check_outputs(args) -> None:
    """Checks every output option set on an argparse namespace (see :data:`OUTPUT_OPTIONS`)."""
    for dest, (option, kind) in OUTPUT_OPTIONS.items():
        value = getattr(args, dest, None)
        if isinstance(value, (str, os.PathLike)) and not getattr(args, "no_" + dest, False):
            check_output(option, value, kind)
