"""Synthetic glove demonstrations (the report's recordings are not public).

``python -m handle_drake.apps.inhand.synthetic handle_drake/apps/inhand/data`` writes
the two shipped recordings:

- ``screw_cap_rotation.json``: thumb, first, middle and ring finger grip a
  screw cap and turn it (Figure 32): the thumb rotates across the palm while
  the three fingers flex one after the other (a wave 0.05 of the motion
  apart), then all release in the same order.
- ``star_rotation.json``: a star prism turned by two strokes of the first and
  middle finger against the thumb (finger gaiting: flex, release, flex).

Each joint follows minimum-jerk strokes (``10 s^3 - 15 s^4 + 6 s^5``, the
profile of human point-to-point movements) between postures, with a 9 Hz
physiological tremor of 0.004 rad, a slow drift and white noise of 0.003 rad,
then is quantised as a CyberGlove would (8-bit counts, ``raw = offset +
angle / gain``; the calibration is stored in the file). Sampled at 50 Hz.
Everything is seeded: the files are reproducible byte for byte.
"""

from __future__ import annotations

import sys
from pathlib import Path

import numpy as np

from handle_drake.apps.inhand.glove import GLOVE_SENSORS, GloveRecording, save_glove

__all__ = ["screw_cap_rotation", "star_rotation", "write_demonstrations", "DATA_DIR"]

DATA_DIR = Path(__file__).parent / "data"
RATE = 50.0  # Hz


def _min_jerk(s):
    s = np.clip(s, 0.0, 1.0)
    return 10 * s**3 - 15 * s**4 + 6 * s**5


def _synthesize(duration, rest, strokes, seed, meta) -> GloveRecording:
    """``rest``: sensor -> angle at rest; ``strokes``: (sensor, t0, t1, delta), normalised t."""
    rng = np.random.default_rng(seed)
    t = np.arange(0.0, duration + 1e-9, 1.0 / RATE)
    s = t / duration
    angles = np.zeros((t.size, len(GLOVE_SENSORS)))
    for name, value in rest.items():
        angles[:, GLOVE_SENSORS.index(name)] = value
    for name, t0, t1, delta in strokes:
        angles[:, GLOVE_SENSORS.index(name)] += delta * _min_jerk((s - t0) / (t1 - t0))
    phase = rng.uniform(0, 2 * np.pi, len(GLOVE_SENSORS))
    angles += 0.004 * np.sin(2 * np.pi * 9.0 * t[:, None] + phase)
    angles += np.cumsum(rng.normal(0, 0.0008, angles.shape), axis=0)  # slow drift
    angles += rng.normal(0, 0.003, angles.shape)
    gain = rng.uniform(0.009, 0.012, len(GLOVE_SENSORS))  # rad per count
    offset = rng.integers(60, 90, len(GLOVE_SENSORS)).astype(float)
    raw = np.clip(np.round(offset + angles / gain), 0, 255)
    return GloveRecording(t, raw, gain, offset, meta)


_GRIP = {"TR": 0.35, "TMCP": 0.25, "TIJ": 0.2, "TAB": 0.6,
         "IMCP": 0.35, "IPIJ": 0.35, "IDIJ": 0.2, "MMCP": 0.35, "MPIJ": 0.35, "MDIJ": 0.2,
         "RMCP": 0.35, "RPIJ": 0.35, "RDIJ": 0.2, "PMCP": 0.2, "PPIJ": 0.2, "PDIJ": 0.1,
         "IMA": 0.15, "MRA": 0.1, "RPA": 0.15, "PA": 0.2, "WP": 0.0, "WY": 0.0}


def screw_cap_rotation(seed: int = 13) -> GloveRecording:
    strokes = [("TR", 0.10, 0.42, 0.30), ("TMCP", 0.10, 0.42, 0.25), ("TIJ", 0.10, 0.42, 0.2),
               ("TR", 0.62, 0.90, -0.30), ("TMCP", 0.62, 0.90, -0.25),
               ("TIJ", 0.62, 0.90, -0.2)]
    for k, (mcp, pij, dij) in enumerate((("IMCP", "IPIJ", "IDIJ"), ("MMCP", "MPIJ", "MDIJ"),
                                         ("RMCP", "RPIJ", "RDIJ"))):
        a, b = 0.14 + 0.05 * k, 0.50 + 0.05 * k
        c, d = 0.62 + 0.05 * k, 0.86 + 0.04 * k
        strokes += [(mcp, a, b, 0.55), (pij, a, b, 0.45), (dij, a, b, 0.3),
                    (mcp, c, d, -0.55), (pij, c, d, -0.45), (dij, c, d, -0.3)]
    meta = {"task": "screw_cap_rotation", "synthetic": True, "seed": seed,
            "fingers": ["TH", "FF", "MF", "RF"],
            "made_by": "handle_drake.apps.inhand.synthetic.screw_cap_rotation"}
    return _synthesize(3.0, _GRIP, strokes, seed, meta)


def star_rotation(seed: int = 29) -> GloveRecording:
    strokes = [("TR", 0.05, 0.30, 0.25), ("TMCP", 0.05, 0.30, 0.2)]
    for mcp, pij, dij in (("IMCP", "IPIJ", "IDIJ"), ("MMCP", "MPIJ", "MDIJ")):
        for a, b, sign in ((0.10, 0.40, 1), (0.45, 0.60, -1), (0.65, 0.95, 1)):
            strokes += [(mcp, a, b, sign * 0.5), (pij, a, b, sign * 0.4),
                        (dij, a, b, sign * 0.25)]
    meta = {"task": "star_rotation", "synthetic": True, "seed": seed,
            "fingers": ["TH", "FF", "MF"],
            "made_by": "handle_drake.apps.inhand.synthetic.star_rotation"}
    return _synthesize(3.0, _GRIP, strokes, seed, meta)


def write_demonstrations(directory=DATA_DIR) -> list[Path]:
    directory = Path(directory)
    return [save_glove(screw_cap_rotation(), directory / "screw_cap_rotation.json"),
            save_glove(star_rotation(), directory / "star_rotation.json")]


if __name__ == "__main__":  # pragma: no cover - a script
    for path in write_demonstrations(sys.argv[1] if len(sys.argv) > 1 else DATA_DIR):
        print(f"wrote {path} ({path.stat().st_size} bytes)")
