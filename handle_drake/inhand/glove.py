"""Data-glove recordings (22-sensor CyberGlove): format, validating loader and saver, calibration.

A recording is one JSON file::

    {"format": "handle_drake.glove", "version": 1,
     "sensors": [22 names, GLOVE_SENSORS order],
     "time": [T values, s, strictly increasing],
     "raw": [[22 values] * T],          # raw sensor readings (CyberGlove: 0..255 counts)
     "calibration": {"gain": [22], "offset": [22]} | null,   # angle = gain * (raw - offset), rad
     "meta": {...}}                      # free text: task, subject, how it was made

Sensors (:data:`GLOVE_SENSORS`): per finger the flexion of the metacarpo-
phalangeal (MCP), proximal (PIJ) and distal (DIJ) joints; the thumb's rotation
across the palm (TR), MCP, interphalangeal joint (IJ) and thumb-index
abduction (TAB); the abductions between finger pairs (IMA index-middle, MRA
middle-ring, RPA ring-little); the palm arch (PA); wrist pitch (WP, flexion) and
yaw (WY, abduction). Without a calibration the raw values are taken as angles
in rad (gain 1, offset 0): the action gist only needs joint variations, and
the optimiser refines their amplitudes (report 5.4.2).
"""

from __future__ import annotations

import json
import math
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

__all__ = ["GLOVE_SENSORS", "MAX_SAMPLE_RATE", "GloveRecording", "load_glove", "save_glove",
           "GloveFormatError"]

GLOVE_SENSORS: tuple[str, ...] = (
    "TR", "TMCP", "TIJ", "TAB",            # thumb: rotation, MCP, IP, thumb-index abduction
    "IMCP", "IPIJ", "IDIJ",                # index (first) finger
    "MMCP", "MPIJ", "MDIJ",                # middle
    "RMCP", "RPIJ", "RDIJ",                # ring
    "PMCP", "PPIJ", "PDIJ",                # little (pinkie)
    "IMA", "MRA", "RPA",                   # abductions between finger pairs
    "PA",                                  # palm arch
    "WP", "WY",                            # wrist pitch (flexion), yaw (abduction)
)
_FORMAT = "handle_drake.glove"
_VERSION = 1
#: Hz: time stamps closer than 1 / MAX_SAMPLE_RATE are refused (a CyberGlove streams at
#: ~100-150 Hz; closer stamps are a unit error, and the gist's smoothing window, in
#: samples, would grow without bound: 1e-12 s apart asked for 745 GiB).
MAX_SAMPLE_RATE = 10_000.0
#: samples per recording (10 minutes at 10 kHz): more is not one demonstration.
MAX_SAMPLES = 6_000_000


class GloveFormatError(ValueError):
    """A glove recording is malformed; the message names the field."""


def _short(value, limit=80) -> str:
    text = repr(value)
    return text if len(text) <= limit else text[: limit - 3] + "..."


@dataclass
class GloveRecording:
    """One demonstration: ``time`` (T,) s, ``raw`` (T, 22) in :data:`GLOVE_SENSORS` order."""

    time: np.ndarray
    raw: np.ndarray
    gain: np.ndarray | None = None  # (22,) rad per raw unit
    offset: np.ndarray | None = None  # (22,) raw units
    meta: dict = field(default_factory=dict)

    def __post_init__(self):
        self.time = _array("time", self.time, 1)
        self.raw = _array("raw", self.raw, 2)
        if self.raw.shape[1] != len(GLOVE_SENSORS):
            raise GloveFormatError(
                f"raw: expected {len(GLOVE_SENSORS)} sensors per sample "
                f"({', '.join(GLOVE_SENSORS)}), got {self.raw.shape[1]}")
        if self.raw.shape[0] != self.time.shape[0]:
            raise GloveFormatError(
                f"raw: expected one row per time stamp ({self.time.shape[0]}), "
                f"got {self.raw.shape[0]}")
        if self.time.shape[0] < 2:
            raise GloveFormatError(f"time: expected at least 2 samples, got {self.time.shape[0]}")
        if self.time.shape[0] > MAX_SAMPLES:
            raise GloveFormatError(
                f"time: expected at most {MAX_SAMPLES} samples, got {self.time.shape[0]}")
        steps = np.diff(self.time)
        if np.any(steps <= 0):
            i = int(np.flatnonzero(steps <= 0)[0])
            raise GloveFormatError(
                f"time: expected strictly increasing time stamps, got {self.time[i]} then "
                f"{self.time[i + 1]} at sample {i + 1}")
        too_close = steps < (1.0 - 1e-6) / MAX_SAMPLE_RATE  # rounding of k / rate passes
        if np.any(too_close):
            i = int(np.flatnonzero(too_close)[0])
            raise GloveFormatError(
                f"time: expected time stamps at least {1.0 / MAX_SAMPLE_RATE:g} s apart (at most "
                f"{MAX_SAMPLE_RATE:g} samples per second), got {self.time[i]!r} then "
                f"{self.time[i + 1]!r} at sample {i + 1} (seconds, not milliseconds?)")
        if (self.gain is None) != (self.offset is None):
            raise GloveFormatError("calibration: expected both gain and offset, or neither")
        if self.gain is not None:
            self.gain = _array("calibration.gain", self.gain, 1, size=len(GLOVE_SENSORS))
            self.offset = _array("calibration.offset", self.offset, 1, size=len(GLOVE_SENSORS))
        if not isinstance(self.meta, dict):
            raise GloveFormatError(f"meta: expected a mapping, got {_short(self.meta)}")

    @property
    def duration(self) -> float:
        return float(self.time[-1] - self.time[0])

    def angles(self) -> np.ndarray:
        """(T, 22) calibrated joint angles, rad: ``gain * (raw - offset)`` (raw if uncalibrated)."""
        if self.gain is None:
            return self.raw.copy()
        return self.gain * (self.raw - self.offset)

    def sensor(self, name: str) -> np.ndarray:
        """Calibrated angles (T,) of the sensor ``name``."""
        if name not in GLOVE_SENSORS:
            raise ValueError(f"sensor: expected one of {GLOVE_SENSORS}, got {name!r}")
        return self.angles()[:, GLOVE_SENSORS.index(name)]


def _has_bool(value) -> bool:
    """A JSON true/false among the numbers (numpy would read it as 1/0)."""
    if isinstance(value, bool):
        return True
    if isinstance(value, list | tuple):
        return any(_has_bool(v) if isinstance(v, list | tuple) else isinstance(v, bool)
                   for v in value)
    return False


def _array(name, value, ndim, size=None) -> np.ndarray:
    try:
        raw = np.asarray(value)
        if raw.dtype.kind not in "iuf" or _has_bool(value):  # strings, booleans, None, ragged
            raise TypeError
        array = raw.astype(float)
    except (TypeError, ValueError, OverflowError):
        raise GloveFormatError(f"{name}: expected numbers, got {_short(value)}") from None
    if array.ndim != ndim:
        raise GloveFormatError(f"{name}: expected a {ndim}-D array, got shape {array.shape}")
    if size is not None and array.shape[0] != size:
        raise GloveFormatError(f"{name}: expected {size} values, got {array.shape[0]}")
    bad = ~np.isfinite(array)
    if bad.any():
        where = tuple(int(i) for i in np.argwhere(bad)[0])
        sensor = f" (sensor {GLOVE_SENSORS[where[1]]})" if ndim == 2 else ""
        raise GloveFormatError(
            f"{name}: expected finite values, got {array[where]} at index {where}{sensor}")
    return array


def save_glove(recording: GloveRecording, path) -> Path:
    """Writes ``recording`` as JSON (raw values with 6 significant digits)."""
    if not isinstance(recording, GloveRecording):
        raise TypeError(f"recording: expected a GloveRecording, got {type(recording).__name__}")
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    document = {
        "format": _FORMAT, "version": _VERSION, "sensors": list(GLOVE_SENSORS),
        "time": [round(float(t), 6) for t in recording.time],
        "raw": [[float(f"{v:.6g}") for v in row] for row in recording.raw],
        "calibration": None if recording.gain is None else {
            "gain": recording.gain.tolist(), "offset": recording.offset.tolist()},
        "meta": recording.meta,
    }
    path.write_text(json.dumps(document, separators=(",", ":")) + "\n")
    return path


def load_glove(path) -> GloveRecording:
    """Reads and validates a recording written by :func:`save_glove` (or by hand).

    Raises FileNotFoundError, or :class:`GloveFormatError` naming the field:
    not JSON, another format, missing or extra sensors, NaN values, time not
    increasing, a calibration of the wrong size.
    """
    from handle_drake.scenario_checks import check_input_file

    path = check_input_file(path, "glove recording")
    try:
        document = json.loads(path.read_text(encoding="utf-8"))
    except (json.JSONDecodeError, UnicodeDecodeError, RecursionError) as error:
        raise GloveFormatError(f"{path}: not a JSON glove recording ({error})") from None
    if not isinstance(document, dict):
        raise GloveFormatError(f"{path}: expected a JSON object, got {type(document).__name__}")
    if document.get("format") != _FORMAT or document.get("version") != _VERSION:
        raise GloveFormatError(
            f"{path}: format {document.get('format')!r} version {document.get('version')!r}, "
            f"expected {_FORMAT!r} version {_VERSION}")
    for key in ("sensors", "time", "raw"):
        if key not in document:
            raise GloveFormatError(f"{path}: missing field {key!r}")
    sensors = document["sensors"]
    if list(sensors) != list(GLOVE_SENSORS):
        missing = [s for s in GLOVE_SENSORS if s not in sensors]
        extra = [s for s in sensors if s not in GLOVE_SENSORS]
        raise GloveFormatError(
            f"{path}: sensors: expected the {len(GLOVE_SENSORS)} CyberGlove sensors in order; "
            f"missing {missing}, unknown {_short(extra)}")
    raw = document["raw"]
    if isinstance(raw, list):
        for i, row in enumerate(raw):
            if not isinstance(row, list) or len(row) != len(GLOVE_SENSORS):
                raise GloveFormatError(
                    f"{path}: raw[{i}]: expected {len(GLOVE_SENSORS)} values, got "
                    f"{len(row) if isinstance(row, list) else _short(row)}")
            if any(v is None or (isinstance(v, float) and math.isnan(v)) for v in row):
                j = next(j for j, v in enumerate(row) if v is None or v != v)
                raise GloveFormatError(
                    f"{path}: raw[{i}]: sensor {GLOVE_SENSORS[j]} has no value ({row[j]!r})")
    calibration = document.get("calibration")
    if calibration is not None and not isinstance(calibration, dict):
        raise GloveFormatError(f"{path}: calibration: expected an object or null")
    try:
        return GloveRecording(
            time=document["time"], raw=raw,
            gain=None if calibration is None else calibration.get("gain"),
            offset=None if calibration is None else calibration.get("offset"),
            meta=document.get("meta") or {})
    except GloveFormatError as error:
        raise GloveFormatError(f"{path}: {error}") from None
