"""Optional packages that only some hardware needs (the extras of pyproject.toml).

A command that needs one (a USB MIDI device needs python-rtmidi, a real
JoyWarrior needs evdev) calls :func:`require_extra` first: without the package
it raises :class:`MissingExtraError`, a one-line error naming the extra to
install (``handle-drake`` prints it and exits 2), instead of an import
traceback from deep inside mido or the driver.
"""

from __future__ import annotations

import importlib

__all__ = ["EXTRAS", "MissingExtraError", "require_extra"]

#: module -> (extra, package, what needs it)
EXTRAS = {
    "rtmidi": ("midi-device", "python-rtmidi", "a MIDI device (mido's rtmidi back end)"),
    "evdev": ("joywarrior", "evdev", "a real JoyWarrior (Linux evdev)"),
}


class MissingExtraError(ImportError):
    """An optional package a command needs is not installed (message: what to install)."""


def require_extra(module: str):
    """Imports and returns ``module`` (a key of :data:`EXTRAS`); raises
    :class:`MissingExtraError` naming the extra when it is not installed."""
    extra, package, purpose = EXTRAS[module]
    try:
        return importlib.import_module(module)
    except ImportError as error:
        raise MissingExtraError(
            f"{purpose} needs {package}, which is not installed ({error}): "
            f"pip install 'handle_drake[{extra}]'", name=module) from None
