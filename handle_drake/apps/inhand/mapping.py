"""The glove -> Shadow hand mapping by the report's four rules (section 5.4.2, Figures 30-31).

1. Same joints, same positions: each flexion sensor drives the Shadow joint at
   the same place (MCP -> J3, thumb rotation -> THJ5, thumb MCP -> THJ2, thumb
   IP -> THJ1, wrist pitch -> WRJ1, wrist yaw -> WRJ2).
2. Abduction sensors only set the initial value (their first sample, held for
   the whole motion): thumb-index -> thumb, index-middle -> first finger,
   index-middle -> middle finger, ring-middle -> ring, little-ring -> little.
   Each finger moves away from the partner of its pair (sign by the Shadow
   J4 axes: +FFJ4 and +MFJ4 turn towards the little finger, +RFJ4 and +LFJ4
   towards the thumb); the index-middle spread is shared half and half.
3. The thumb-index abduction drives both thumb abduction joints, THJ4 and
   THJ3 (their axes are parallel; THJ2 and THJ1 flex in the other plane).
4. LFJ5 (the little finger's carpometacarpal joint) is always 0; the palm
   arch sensor is not used.

J1/J2: the glove's PIJ and DIJ sum to the Shadow J0 = J1 + J2 of the finger;
with the coupling ``J1 = ratio * J2`` the command is ``J2 = J0 / (1 + ratio)``.
Commands are clipped to the hand's command limits.
"""

from __future__ import annotations

import numpy as np

from handle_drake.apps.inhand.glove import GLOVE_SENSORS, GloveRecording
from handle_drake.base.hands import actuated_position_limits, get_hand_spec

__all__ = ["glove_to_shadow", "ABDUCTION_RULES", "FLEXION_RULES"]

# Rule 1: Shadow command joint <- glove sensor (angle copied).
FLEXION_RULES: dict[str, str] = {
    "WRJ2": "WY", "WRJ1": "WP",
    "FFJ3": "IMCP", "MFJ3": "MMCP", "RFJ3": "RMCP", "LFJ3": "PMCP",
    "THJ5": "TR", "THJ2": "TMCP", "THJ1": "TIJ",
}
# J0 = PIJ + DIJ, command J2 = J0 / (1 + ratio).
_J0_RULES = {"FF": ("IPIJ", "IDIJ"), "MF": ("MPIJ", "MDIJ"), "RF": ("RPIJ", "RDIJ"),
             "LF": ("PPIJ", "PDIJ")}
# Rules 2 and 3: joint <- (sensor, factor) at the first sample only.
ABDUCTION_RULES: dict[str, tuple[str, float]] = {
    "THJ4": ("TAB", 1.0), "THJ3": ("TAB", 1.0),   # rule 3: both thumb abduction joints
    "FFJ4": ("IMA", -0.5),                         # index away from middle (towards the thumb)
    "MFJ4": ("IMA", 0.5),                          # middle away from index
    "RFJ4": ("MRA", -1.0),                         # ring away from middle
    "LFJ4": ("RPA", -1.0),                         # little away from ring
}


def glove_to_shadow(recording: GloveRecording | np.ndarray, coupling_ratio: float = 1.0,
                    clip: bool = True) -> np.ndarray:
    """(T, 20) Shadow commands (rad, actuated order) from a recording or its (T, 22) angles."""
    angles = recording.angles() if isinstance(recording, GloveRecording) else \
        np.asarray(recording, dtype=float)
    if angles.ndim != 2 or angles.shape[1] != len(GLOVE_SENSORS):
        raise ValueError(f"angles: expected shape (T, {len(GLOVE_SENSORS)}), got {angles.shape}")
    if not np.all(np.isfinite(angles)):
        raise ValueError("angles: expected finite values, got NaN or inf")
    spec = get_hand_spec("shadow")
    names = list(spec.actuated_joint_names)
    column = {name: angles[:, GLOVE_SENSORS.index(name)] for name in GLOVE_SENSORS}
    ratio = float(coupling_ratio)
    if not (np.isfinite(ratio) and ratio > 0):
        raise ValueError(f"coupling_ratio: expected a finite value > 0, got {coupling_ratio}")
    out = np.zeros((angles.shape[0], len(names)))
    for joint, sensor in FLEXION_RULES.items():
        out[:, names.index(joint)] = column[sensor]
    for finger, (pij, dij) in _J0_RULES.items():
        out[:, names.index(f"{finger}J2")] = (column[pij] + column[dij]) / (1.0 + ratio)
    for joint, (sensor, factor) in ABDUCTION_RULES.items():
        out[:, names.index(joint)] = factor * column[sensor][0]
    out[:, names.index("LFJ5")] = 0.0  # rule 4
    if clip:
        lower, upper = actuated_position_limits(spec, ratio)
        out = np.clip(out, lower, upper)
    return out
