"""MIDI ports: a real device through mido + python-rtmidi, an in-process port,
and Meshcat sliders standing in for the faders.

Every port here is a ``mido`` port (``iter_pending()`` / ``poll()`` to read,
``send(message)`` to write), so the systems in :mod:`handle_drake.midi.systems`
take any of them:

- :func:`open_device_ports`: the real controller (a class-compliant USB MIDI
  device) via mido's default backend, python-rtmidi (ALSA sequencer on Linux,
  CoreMIDI, WinMM). Needs ``/dev/snd/seq`` on Linux; without it the error
  says so instead of rtmidi's ``SystemError``.
- :func:`in_process_pair`: two connected :class:`InProcessPort` s; what one
  sends the other receives, thread-safe, no OS MIDI layer. For tests,
  simulation, benchmarks and machines without MIDI.
- :class:`MeshcatFaderPort`: Meshcat sliders as faders (and a button as the
  mode button); it *sends* control-change messages when a slider moves, and
  *receives* fader feedback by moving the sliders.
"""

from __future__ import annotations

import os
import sys
import threading

import mido
import mido.ports

from handle_drake.midi.codec import control_message
from handle_drake.midi.mapping import MidiMapping

__all__ = [
    "InProcessPort",
    "MeshcatFaderPort",
    "MidiPortError",
    "device_port_names",
    "in_process_pair",
    "open_device_ports",
]


class MidiPortError(ValueError):
    """A MIDI port could not be opened (no such device, no MIDI system)."""


class InProcessPort(mido.ports.BaseIOPort):
    """One end of an in-process MIDI cable (make both ends with :func:`in_process_pair`).

    ``send`` appends a copy to the peer's queue; ``receive``/``poll``/
    ``iter_pending`` read this end's queue.
    """

    def __init__(self, name: str = "in-process", **kwargs):
        self._peer = None
        self._ready = threading.Condition()
        super().__init__(name, **kwargs)

    def _open(self, **kwargs):
        pass

    def _send(self, message):
        peer = self._peer
        if peer is None or peer.closed:
            return  # like a cable with nothing at the other end
        with peer._ready:
            peer._messages.append(message)
            peer._ready.notify_all()

    def _receive(self, block=True):
        # BaseInput.receive polls with a short sleep when blocking; waiting on the
        # condition here instead wakes up as soon as a message arrives.
        if block and not self._messages:
            with self._ready:
                self._ready.wait_for(lambda: self._messages or self.closed, timeout=0.05)
        return None


def in_process_pair(name: str = "in-process") -> tuple[InProcessPort, InProcessPort]:
    """Two connected ports ``(device_end, host_end)``: each receives what the other sends."""
    a, b = InProcessPort(f"{name} (device)"), InProcessPort(f"{name} (host)")
    a._peer, b._peer = b, a
    return a, b


ALSA_SEQUENCER = "/dev/snd/seq"


def _check_midi_system() -> None:
    """Refuses before python-rtmidi is asked where its ALSA back end cannot work.

    Without the ALSA sequencer device, rtmidi's ``MidiIn()`` raises a
    ``SystemError`` *and* libasound prints its own line to the process's
    stderr (C level, past Python's ``sys.stderr``); checking the device first
    keeps the failure to the one line of :class:`MidiPortError`. Only for
    mido's rtmidi back end with the ALSA (or the default) API on Linux: other
    back ends and APIs are asked as they are.
    """
    backend = mido.backend
    if (sys.platform.startswith("linux") and backend.name == "mido.backends.rtmidi"
            and backend.api in (None, "LINUX_ALSA") and not os.path.exists(ALSA_SEQUENCER)):
        raise MidiPortError(
            f"no MIDI system available: the ALSA sequencer {ALSA_SEQUENCER} does not exist "
            "(python-rtmidi needs it on Linux: load the snd-seq module, or pass /dev/snd into "
            "the container); use the in-process port or Meshcat sliders (--meshcat) instead")


def _check_backend_installed() -> None:
    """mido's default back end (python-rtmidi) is an extra: without it, one line
    naming the extra (:class:`~handle_drake.extras.MissingExtraError`)."""
    if mido.backend.name == "mido.backends.rtmidi":
        from handle_drake.extras import require_extra

        require_extra("rtmidi")


def device_port_names() -> tuple[list[str], list[str]]:
    """(input names, output names) of the MIDI system; raises :class:`MidiPortError`
    (or :class:`~handle_drake.extras.MissingExtraError` without python-rtmidi)."""
    _check_backend_installed()
    _check_midi_system()
    try:
        return list(mido.get_input_names()), list(mido.get_output_names())
    except Exception as error:  # rtmidi raises SystemError without an ALSA sequencer
        raise MidiPortError(
            "no MIDI system available (python-rtmidi: "
            f"{' '.join(str(error).split())[:160]}); on Linux the ALSA sequencer "
            f"{ALSA_SEQUENCER} is needed; use the in-process port or Meshcat sliders instead"
        ) from None


def open_device_ports(name: str):
    """Opens ``(input, output)`` of the first MIDI device whose name contains
    ``name`` (case-insensitive), e.g. the mapping's ``port_name``."""
    if not isinstance(name, str) or not name.strip():
        raise ValueError(f"port name: expected a non-empty string, got {name!r}")
    inputs, outputs = device_port_names()
    pick = [n for n in inputs if name.lower() in n.lower()]
    pick_out = [n for n in outputs if name.lower() in n.lower()]
    if not pick or not pick_out:
        raise MidiPortError(
            f"no MIDI device matching {name!r}; inputs: {inputs or 'none'}, "
            f"outputs: {outputs or 'none'}"
        )
    try:
        return mido.open_input(pick[0]), mido.open_output(pick_out[0])
    except Exception as error:
        raise MidiPortError(f"cannot open MIDI device {pick[0]!r}: {error}") from None


class MeshcatFaderPort(mido.ports.BaseIOPort):
    """Meshcat sliders standing in for the faders (no MIDI device needed).

    One slider per fader of the mapping (range 0-127, the 7-bit value) and a
    Meshcat button for the ``mode_button``. Polling (``iter_pending``) yields
    a control-change message for every slider whose value changed since the
    last poll and a note on/off pair per button click, exactly what the device
    would send; ``send`` of a fader's control change moves its slider (the
    motorised-fader feedback).
    """

    def __init__(self, meshcat, mapping: MidiMapping, mode_button: str | None = "mode",
                 prefix: str = "MIDI "):
        self._meshcat = meshcat
        self._mapping = mapping
        self._faders = [mapping.control(n) for n in mapping.names("fader")]
        self._labels = [f"{prefix}{c.name}" for c in self._faders]
        self._mode = mapping.control(mode_button) if mode_button else None
        self._button = f"{prefix}{mode_button}" if mode_button else None
        for label in self._labels:
            meshcat.AddSlider(label, 0, 127, 1, 0)
        if self._button:
            meshcat.AddButton(self._button)
        self._values = [0] * len(self._faders)
        self._clicks = 0
        super().__init__(f"meshcat sliders ({mapping.device})")

    def _open(self, **kwargs):
        pass

    def _close(self):
        for label in self._labels:
            self._meshcat.DeleteSlider(label, strict=False)
        if self._button:
            self._meshcat.DeleteButton(self._button, strict=False)

    def _receive(self, block=True):
        for i, (control, label) in enumerate(zip(self._faders, self._labels, strict=True)):
            value = int(round(self._meshcat.GetSliderValue(label)))
            if value != self._values[i]:
                self._values[i] = value
                self._messages.append(control_message(control, value))
        if self._button:
            clicks = self._meshcat.GetButtonClicks(self._button)
            for _ in range(clicks - self._clicks):
                self._messages.append(control_message(self._mode, 1))
                self._messages.append(control_message(self._mode, 0))
            self._clicks = clicks
        return None

    def _send(self, message):
        if message.type != "control_change":
            return
        for i, control in enumerate(self._faders):
            if (control.channel, control.number) == (message.channel, message.control):
                self._values[i] = message.value
                self._meshcat.SetSliderValue(self._labels[i], message.value)
