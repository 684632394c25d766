"""Taxel-array profiles: what a pad of pressure cells reports (size, pitch, range, noise,
quantisation, rate).

A :class:`TaxelProfile` is a grid of ``rows x cols`` cells of ``pitch_row x pitch_col``
(m) centred on a pad's face; each cell reports the mean normal pressure over its patch
(Pa). The device samples at ``rate_hz`` and holds the sample, adds white noise
(``noise_std_pa``, seeded by ``(seed, sample index)``), clips at ``[0, range_pa]``
(saturation) and rounds to ``bits`` of unsigned resolution: one count is
``lsb = range_pa / (2**bits - 1)``.

Point contact has no pressure field: ``point_sigma`` (m) is the standard deviation of
the Gaussian over which a point contact's normal force is spread across the cells (each
cell gets the Gaussian's integral over its patch; what falls off the grid is lost, as
on a real pad). The default, 1.5 mm, is about the Hertz contact radius of a few newtons
between a silicone skin and a rigid object.

Profiles (ours): ``pad4x4``, a 4 x 4 grid on the Shadow hand's 14 x 18 mm distal pad
(the layout of a PST/DSA-like fingertip array: 3.5 x 4.5 mm cells, 12 bits over 400 kPa,
1 kPa noise, 100 Hz); ``palm6x6``, a 6 x 6 grid of 10 mm cells on the palm's palmar face;
``skin5mm``, a skin around the palmar half of each proximal and middle phalanx (5 mm
rows along it, 4.5 mm of arc across: 6 columns cover about 170 degrees of a 9 mm capsule).
"""

from __future__ import annotations

import dataclasses as dc
import math

import numpy as np

__all__ = ["TaxelProfile", "PROFILES", "get_profile"]

#: Accepted ranges: cells of 0.1..50 mm, up to 64 x 64 per pad, 1 Pa..100 MPa, 1..10 kHz.
LIMITS = {"pitch": (1e-4, 0.05), "cells": (1, 64), "range_pa": (1.0, 1e8),
          "rate_hz": (1.0, 10_000.0), "point_sigma": (1e-5, 0.02)}


@dc.dataclass(frozen=True)
class TaxelProfile:
    """One pad's taxel grid (see the module doc).

    Attributes:
        name: the key in :data:`PROFILES`.
        rows, cols: cells along the pad (the finger's length) and across it.
        pitch_row, pitch_col: cell size (m) along and across.
        range_pa: full scale (Pa): readings saturate there.
        bits: unsigned resolution over ``[0, range_pa]`` (2..24).
        rate_hz: sample rate (Hz); readings are held between samples.
        noise_std_pa: white noise per cell and sample (Pa).
        point_sigma: spread (m) of a point contact's force over the cells.
    """

    name: str
    rows: int
    cols: int
    pitch_row: float
    pitch_col: float
    range_pa: float = 4.0e5
    bits: int = 12
    rate_hz: float = 100.0
    noise_std_pa: float = 1.0e3
    point_sigma: float = 1.5e-3
    description: str = ""

    def __post_init__(self):
        for field in ("rows", "cols"):
            value = getattr(self, field)
            low, high = LIMITS["cells"]
            if isinstance(value, bool) or not isinstance(value, int | np.integer) \
                    or not low <= value <= high:
                raise ValueError(f"{field}: expected an integer in [{low}, {high}], got {value!r}")
        for field, key in (("pitch_row", "pitch"), ("pitch_col", "pitch"),
                           ("range_pa", "range_pa"), ("rate_hz", "rate_hz"),
                           ("point_sigma", "point_sigma")):
            value = getattr(self, field)
            low, high = LIMITS[key]
            if isinstance(value, bool) or not isinstance(value, int | float | np.number) \
                    or not math.isfinite(value) or not low <= value <= high:
                raise ValueError(f"{field}: expected a number in [{low:g}, {high:g}], "
                                 f"got {value!r}")
            object.__setattr__(self, field, float(value))
        if isinstance(self.bits, bool) or not isinstance(self.bits, int | np.integer) \
                or not 2 <= self.bits <= 24:
            raise ValueError(f"bits: expected an integer in [2, 24], got {self.bits!r}")
        value = self.noise_std_pa
        if isinstance(value, bool) or not isinstance(value, int | float | np.number) \
                or not math.isfinite(value) or value < 0:
            raise ValueError(f"noise_std_pa: expected a finite number >= 0, got {value!r}")
        object.__setattr__(self, "noise_std_pa", float(value))

    @property
    def cells(self) -> int:
        return self.rows * self.cols

    @property
    def cell_area(self) -> float:
        """m^2 of one cell's patch."""
        return self.pitch_row * self.pitch_col

    @property
    def lsb(self) -> float:
        """One count in Pa."""
        return self.range_pa / (2 ** self.bits - 1)

    @property
    def period(self) -> float:
        return 1.0 / self.rate_hz

    def cell_centres(self) -> np.ndarray:
        """(rows * cols, 2) cell centres ``(u, v)`` in the pad frame (m): ``u`` across the
        pad (pad x), ``v`` along it (pad y); row-major, row 0 at the most negative v."""
        u = (np.arange(self.cols) - (self.cols - 1) / 2) * self.pitch_col
        v = (np.arange(self.rows) - (self.rows - 1) / 2) * self.pitch_row
        vv, uu = np.meshgrid(v, u, indexing="ij")
        return np.column_stack([uu.ravel(), vv.ravel()])

    def quantise(self, pressures: np.ndarray, noise: np.ndarray | None = None) -> np.ndarray:
        """Counts (integers, as floats) of ideal ``pressures`` (Pa) plus ``noise`` (Pa):
        clipped at ``[0, range_pa]``, rounded to the nearest count."""
        p = np.asarray(pressures, dtype=float)
        if noise is not None:
            p = p + noise
        return np.rint(np.clip(p, 0.0, self.range_pa) / self.lsb)

    def replace(self, **changes) -> TaxelProfile:
        return dc.replace(self, **changes)


PROFILES = {
    "pad4x4": TaxelProfile(
        "pad4x4", rows=4, cols=4, pitch_row=0.0045, pitch_col=0.0035,
        description="4 x 4 cells on the Shadow distal pad (14 x 18 mm), 12 bit, 400 kPa"),
    "pad6x4": TaxelProfile(
        "pad6x4", rows=6, cols=4, pitch_row=0.003, pitch_col=0.0035,
        description="6 x 4 cells on the Shadow distal pad (14 x 18 mm), 12 bit, 400 kPa"),
    "palm6x6": TaxelProfile(
        "palm6x6", rows=6, cols=6, pitch_row=0.010, pitch_col=0.010, range_pa=1.0e5,
        noise_std_pa=2.5e2, description="6 x 6 cells of 10 mm on the palm, 12 bit, 100 kPa"),
    "skin5mm": TaxelProfile(
        "skin5mm", rows=8, cols=6, pitch_row=0.005, pitch_col=0.0045,
        description="skins on the proximal and middle phalanges: 5 mm rows along the "
                    "capsule (as many as fit, up to 8), 6 columns of 4.5 mm of arc across "
                    "its palmar half, 12 bit, 400 kPa"),
}


def get_profile(name: str) -> TaxelProfile:
    if name not in PROFILES:
        raise ValueError(f"unknown taxel profile {name!r}; expected one of {sorted(PROFILES)}")
    return PROFILES[name]
