"""Output paths checked before any work starts (the CLI's ``--html``, ``--db``, ...).

A run of minutes must not end in an ``OSError`` traceback because its output
path is a directory, lies in a missing or read-only place, or has a name the
file system refuses. :func:`check_output` finds that out first, without
creating anything, and raises ``ValueError`` naming the option, what was
expected and what was got.
"""

from __future__ import annotations

import os
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
        return path
    if not ancestor.is_dir():
        raise ValueError(f"{option}: expected a path under a directory, but {short_path(ancestor)} "
                         f"is a file")
    if not os.access(ancestor, os.W_OK | os.X_OK):
        raise ValueError(f"{option}: cannot create {shown}: {short_path(ancestor)} is read-only")
    name_max = _limit(ancestor, "PC_NAME_MAX", 255)
    for part in path.parts:
        if len(os.fsencode(part)) > name_max:
            raise ValueError(f"{option}: expected file names of at most {name_max} bytes, got "
                             f"one of {len(os.fsencode(part))} ({part[:40]}...)")
    path_max = _limit(ancestor, "PC_PATH_MAX", 4096)
    if len(os.fsencode(str(path.absolute()))) >= path_max:
        raise ValueError(f"{option}: expected a path shorter than {path_max} bytes, got {shown}")
    return path


def check_outputs(args) -> None:
    """Checks every output option set on an argparse namespace (see :data:`OUTPUT_OPTIONS`)."""
    for dest, (option, kind) in OUTPUT_OPTIONS.items():
        value = getattr(args, dest, None)
        if isinstance(value, (str, os.PathLike)) and not getattr(args, "no_" + dest, False):
            check_output(option, value, kind)
