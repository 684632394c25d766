"""The control -> MIDI message mapping: a data file the user edits.

The iControls Pro's mapping from its faders, knobs, jog wheel and buttons to
MIDI messages is user-configurable on the real device, so here it is a YAML
file (default: ``handle_drake/devices/midi/icontrols_pro.yaml``, commented) read into
typed dataclasses with Drake's ``yaml_load_typed``, like a scenario (so, as
``scenario.py``, this module must not use ``from __future__ import
annotations``). Both the
simulated controller (which sends) and the hand-control interface (which
receives) read the same file.
"""

import dataclasses as dc
from pathlib import Path

from pydrake.common.yaml import yaml_load_typed

from handle_drake.base.checks import check_yaml_text, read_text_file

__all__ = [
    "CONTROL_KINDS",
    "DEFAULT_MAPPING_FILE",
    "RELATIVE_ENCODINGS",
    "ControlMap",
    "MidiMapping",
    "LoadMidiMapping",
]

CONTROL_KINDS = ("fader", "knob", "jog", "button")
RELATIVE_ENCODINGS = ("signed_bit", "twos_complement", "binary_offset")
DEFAULT_MAPPING_FILE = Path(__file__).resolve().parent / "icontrols_pro.yaml"


@dc.dataclass
class ControlMap:
    """One physical control and the MIDI message it sends.

    ``channel`` 0-15 (mido numbering), ``number`` the controller number
    (fader, knob, jog) or the note number (button), 0-127.
    """

    name: str = ""
    kind: str = "fader"
    channel: int = 0
    number: int = 0

    @property
    def message_type(self) -> str:
        return "note" if self.kind == "button" else "control_change"

    @property
    def relative(self) -> bool:
        return self.kind in ("knob", "jog")


@dc.dataclass
class MidiMapping:
    """The device's mapping (see the default file for the meaning of each field)."""

    device: str = "iControls Pro"
    # A substring of the mido port name of the real device.
    port_name: str = "iControls"
    relative_encoding: str = "signed_bit"
    knob_ticks_per_turn: int = 24
    jog_ticks_per_turn: int = 64
    controls: list[ControlMap] = dc.field(default_factory=list)

    def __post_init__(self):
        self._index = None

    def validate(self) -> "MidiMapping":
        """Checks every field; raises ``ValueError`` naming the field. Returns self."""
        if self.relative_encoding not in RELATIVE_ENCODINGS:
            raise ValueError(
                f"relative_encoding: expected one of {list(RELATIVE_ENCODINGS)}, "
                f"got {self.relative_encoding!r}"
            )
        for name in ("knob_ticks_per_turn", "jog_ticks_per_turn"):
            value = getattr(self, name)
            if not (isinstance(value, int) and 1 <= value <= 10000):
                raise ValueError(f"{name}: expected an integer in [1, 10000], got {value!r}")
        if not self.controls:
            raise ValueError("controls: expected at least one control, got none")
        names, keys = set(), {}
        for i, control in enumerate(self.controls):
            where = f"controls[{i}] ({control.name!r})"
            if not control.name:
                raise ValueError(f"controls[{i}].name: expected a non-empty name")
            if control.name in names:
                raise ValueError(f"{where}: duplicate control name")
            names.add(control.name)
            if control.kind not in CONTROL_KINDS:
                raise ValueError(
                    f"{where}.kind: expected one of {list(CONTROL_KINDS)}, got {control.kind!r}"
                )
            if not (isinstance(control.channel, int) and 0 <= control.channel <= 15):
                raise ValueError(f"{where}.channel: expected 0-15, got {control.channel!r}")
            if not (isinstance(control.number, int) and 0 <= control.number <= 127):
                raise ValueError(f"{where}.number: expected 0-127, got {control.number!r}")
            key = (control.message_type, control.channel, control.number)
            if key in keys:
                raise ValueError(
                    f"{where}: sends the same message as {keys[key]!r} "
                    f"({key[0]}, channel {key[1]}, number {key[2]})"
                )
            keys[key] = control.name
        self._index = None
        return self

    # ---- look-ups -------------------------------------------------------------
    def _build_index(self):
        if self._index is None:
            self._index = (
                {c.name: c for c in self.controls},
                {(c.message_type, c.channel, c.number): c for c in self.controls},
                {c.channel for c in self.controls},
            )
        return self._index

    def control(self, name: str) -> ControlMap:
        by_name = self._build_index()[0]
        if name not in by_name:
            raise ValueError(f"control {name!r} is not in the mapping; expected one of "
                             f"{[c.name for c in self.controls]}")
        return by_name[name]

    def find(self, message_type: str, channel: int, number: int) -> ControlMap | None:
        """The control sending ``(message_type, channel, number)``, or None."""
        return self._build_index()[1].get((message_type, channel, number))

    def has_channel(self, channel: int) -> bool:
        return channel in self._build_index()[2]

    def names(self, kind: str | None = None) -> list[str]:
        """Control names (of one kind) in file order."""
        return [c.name for c in self.controls if kind is None or c.kind == kind]

    def ticks_per_turn(self, control: ControlMap | str) -> int:
        control = self.control(control) if isinstance(control, str) else control
        if control.kind == "jog":
            return self.jog_ticks_per_turn
        if control.kind == "knob":
            return self.knob_ticks_per_turn
        raise ValueError(f"control {control.name!r} is a {control.kind}, not a rotary control")


def LoadMidiMapping(filename: str | Path | None = None, data: str | None = None) -> MidiMapping:
    """Reads a mapping file (default: the shipped iControls Pro mapping), then an
    optional YAML override string; validates it.

    Raises:
        FileNotFoundError: no such file.
        ValueError: malformed YAML, an unknown field, or an invalid value.
    """

    path = DEFAULT_MAPPING_FILE if filename is None else Path(filename)
    mapping = MidiMapping()
    for text, source in ((read_text_file(path, "MIDI mapping"), str(path)), (data, "override")):
        if text is None or not text.strip():
            continue
        # Field-naming refusals of duplicate keys, unknown tags and wrong kinds first.
        check_yaml_text(text, MidiMapping, source, what="MIDI mapping")
        try:
            mapping = yaml_load_typed(schema=MidiMapping, data=text, defaults=mapping)
        except Exception as error:  # yaml.YAMLError, RuntimeError, ValueError, TypeError
            message = " ".join(str(error).strip().splitlines())[:400]
            raise ValueError(f"invalid MIDI mapping ({source}): {message}") from None
    mapping.__post_init__()
    return mapping.validate()
