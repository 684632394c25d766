"""Analyses of grasp data: synergies from recordings, and Table 1 re-derived.

:func:`rederive_table1` repeats the report's section 3.2.1 analysis on any
:class:`~handle_drake.grasp.recordings.GraspRecords`: forward kinematics of
each posture, the grasp centre between the class's finger contacts, and per
class a linear least-squares fit of the centre against the object size, in
the report's units and frame (mm, origin at WRJ1; see
:mod:`~handle_drake.grasp.taxonomy`), so the result can be read side by side
with Table 1.
"""

from __future__ import annotations

import numpy as np

from handle_drake.base.hands import get_hand_spec
from handle_drake.grasp.kinematics import GraspKinematics
from handle_drake.grasp.recordings import GraspRecords, load_grasps
from handle_drake.grasp.synergies import fit_record_synergies, reconstruction_error_vs_k
from handle_drake.grasp.synthetic import DATA_FILE
from handle_drake.grasp.taxonomy import GRASP_CLASSES, GraspClass, palm_to_report_mm

__all__ = ["grasp_centres", "rederive_table1", "fit_record_synergies", "table1_markdown"]


def grasp_centres(records: GraspRecords, kinematics: GraspKinematics | None = None) -> np.ndarray:
    """(N, 3) grasp centres ``p_PC`` (m, palm frame) of recorded postures."""
    kin = kinematics or GraspKinematics()
    return np.array([kin.grasp_centre(q, c) for q, c in zip(records.q, records.grasp_classes,
                                                             strict=True)])


def rederive_table1(records: GraspRecords, kinematics: GraspKinematics | None = None,
                    min_sizes: int = 2) -> dict[GraspClass, dict]:
    """Per class: Table-1 style coefficients fitted to the data.

    Returns ``{class: {"table1": (x0, dx, y0, dy, z0, dz), "n": count,
    "rms_mm": residual per axis}}`` (mm and mm/mm, report frame). Classes with
    fewer than ``min_sizes`` distinct sizes are left out (no slope).
    """
    centres_mm = palm_to_report_mm(grasp_centres(records, kinematics))
    sizes_mm = records.sizes * 1e3
    out = {}
    for cls in GRASP_CLASSES:
        mask = np.array([c is cls for c in records.grasp_classes])
        if len(np.unique(sizes_mm[mask])) < min_sizes:
            continue
        design = np.column_stack([np.ones(mask.sum()), sizes_mm[mask]])
        coef, *_ = np.linalg.lstsq(design, centres_mm[mask], rcond=None)
        resid = centres_mm[mask] - design @ coef
        out[cls] = {
            "table1": tuple(float(v) for pair in zip(coef[0], coef[1], strict=True) for v in pair),
            "n": int(mask.sum()),
            "rms_mm": np.sqrt(np.mean(resid**2, axis=0)),
        }
    return out


def table1_markdown(derived: dict[GraspClass, dict]) -> str:
    """Side-by-side table: report Table 1 vs. the re-derived coefficients."""
    lines = ["| class | n | x0 | dx | y0 | dy | z0 | dz |", "|---|---|---|---|---|---|---|---|"]
    for cls, info in GRASP_CLASSES.items():
        rep = " | ".join(f"{v:.2f}" for v in info.table1)
        lines.append(f"| {cls.value} (report) | | {rep} |")
        if cls in derived:
            d = derived[cls]
            got = " | ".join(f"{v:.2f}" for v in d["table1"])
            lines.append(f"| {cls.value} (data) | {d['n']} | {got} |")
    return "\n".join(lines)


def reconstruction_table(records: GraspRecords, k_max: int = 8) -> str:
    """Markdown table of the reconstruction error (rad RMS) against k, global synergies."""
    spec = get_hand_spec("shadow")
    res = reconstruction_error_vs_k(records.q, spec.joint_names, spec.actuated_joint_names,
                                    k_max=k_max)
    lines = ["| k | explained variance | train RMS (rad) | 5-fold test RMS (rad) | max abs (rad) |",
             "|---|---|---|---|---|"]
    for k in res["k"]:
        lines.append(f"| {k} | {res['explained'][k]:.3f} | {res['train_rms'][k]:.4f} | "
                     f"{res['test_rms'][k]:.4f} | {res['max_abs'][k]:.3f} |")
    return "\n".join(lines)


def main(argv=None) -> int:
    """``python -m handle_drake.grasp.analysis [FILE]``: tables for a recording file."""
    import argparse


    parser = argparse.ArgumentParser(description="Synergy and grasp-centre tables of recordings")
    parser.add_argument("file", nargs="?", default=str(DATA_FILE))
    args = parser.parse_args(argv)
    spec = get_hand_spec("shadow")
    records = load_grasps(args.file, (spec.joint_lower_limits, spec.joint_upper_limits))
    print(f"{len(records)} grasps from {args.file}\n")
    print(reconstruction_table(records))
    print()
    print(table1_markdown(rederive_table1(records)))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
