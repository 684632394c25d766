"""A synthetic, "human-like" grasp data set (the report's recordings are not public).

For every grasp class, object shape and size, and for each of a few synthetic
"experimenters", :meth:`GraspKinematics.solve_grasp` solves a Drake
``InverseKinematics`` problem:

- the class's finger contact points lie on the object surface, symmetric about
  the object centre (contact layout of :func:`kinematics.contact_layout`),
  with the finger pads facing the object (angle <= 40 deg),
- joint limits, the J1 = ratio * J2 coupling, wrist at zero,
- no penetration between hand and object or between fingers (>= -2 mm),
- cost: squared distance to the class's posture prior (:data:`POSTURE_PRIORS`),
  plus a weak pull of the object centre towards the report's Table 1 centre
  ("experimenters hold the object where humans do").

Experimenter-like variation: each experimenter has a fixed style offset of
the posture prior (std 0.06 rad per joint), each grasp adds 0.03 rad noise
and a 2 mm random shift of the contact targets along the surface. A grasp is
kept only if the solver succeeds and every contact lies within 1 mm of the
surface; a failed case is retried (up to ``attempts`` draws in all), each
retry with a wider posture noise (0.03 + 0.05 * attempt rad).

Run ``python -m handle_drake.grasp.synthetic [--out FILE] [--seed N]``.
"""

from __future__ import annotations

import argparse
import sys
from datetime import UTC, datetime, timedelta
from pathlib import Path

import numpy as np

from handle_drake.grasp.kinematics import GraspKinematics, object_dims_for
from handle_drake.grasp.recordings import SHADOW_JOINT_NAMES, GraspRecords, save_grasps
from handle_drake.grasp.taxonomy import GRASP_CLASSES, GraspClass, grasp_info

__all__ = ["POSTURE_PRIORS", "CLASS_SHAPES", "posture_prior", "generate"]

DATA_FILE = Path(__file__).resolve().parent / "data" / "synthetic_grasps.csv"

_THUMB = dict(THJ5=0.3, THJ4=1.1, THJ3=0.0, THJ2=0.2, THJ1=0.3)


def _fingers(**flex) -> dict[str, float]:
    out = {}
    for finger, (j3, j2) in flex.items():
        out[f"{finger.upper()}J3"] = j3
        out[f"{finger.upper()}J2"] = j2
    return out


# Posture priors (rad; J1 follows J2). Hand-made from the Feix et al.
# descriptions of the classes: which fingers oppose, which are curled away.
POSTURE_PRIORS: dict[GraspClass, dict[str, float]] = {
    GraspClass.PALMAR_PINCH: {**_THUMB, **_fingers(ff=(0.8, 0.5), mf=(0.4, 0.3), rf=(0.4, 0.3),
                                                   lf=(0.4, 0.3))},
    GraspClass.TIP_PINCH: {**_THUMB, "THJ1": 0.6, **_fingers(ff=(0.9, 0.9), mf=(0.5, 0.6),
                                                             rf=(0.5, 0.6), lf=(0.5, 0.6))},
    # Ring and little fingers only slightly flexed: curled further they reach
    # under the object (IK collision failures with 0.9 rad).
    GraspClass.TRIPOD: {**_THUMB, **_fingers(ff=(0.8, 0.5), mf=(0.8, 0.5), rf=(0.3, 0.3),
                                             lf=(0.3, 0.3))},
    GraspClass.WRITING_TRIPOD: {**_THUMB, **_fingers(ff=(0.7, 0.6), mf=(0.9, 0.9), rf=(1.2, 1.2),
                                                     lf=(1.2, 1.2))},
    GraspClass.LATERAL: {"THJ5": 0.0, "THJ4": 0.5, "THJ1": 0.3,
                         **_fingers(ff=(1.2, 1.2), mf=(1.3, 1.3), rf=(1.3, 1.3), lf=(1.3, 1.3))},
    GraspClass.LATERAL_TRIPOD: {"THJ5": 0.0, "THJ4": 0.6, "THJ1": 0.3,
                                **_fingers(ff=(1.1, 1.1), mf=(0.8, 0.8), rf=(1.3, 1.3),
                                           lf=(1.3, 1.3))},
    GraspClass.ADDUCTION_GRIP: {"THJ4": 0.3, **_fingers(ff=(0.2, 0.2), mf=(0.2, 0.2),
                                                        rf=(0.2, 0.2), lf=(0.2, 0.2))},
    GraspClass.PARALLEL_EXTENSION: {**_THUMB, "THJ1": 0.0,
                                    **_fingers(ff=(0.9, 0.3), mf=(0.9, 0.3), rf=(0.9, 0.3),
                                               lf=(0.9, 0.3))},
}

CLASS_SHAPES = ("sphere", "cylinder", "box")


def posture_prior(name, coupling_ratio: float = 1.0) -> np.ndarray:
    """The (24,) prior posture of a class (rad, ``SHADOW_JOINT_NAMES`` order)."""
    prior = POSTURE_PRIORS[grasp_info(name).grasp_class]
    q = np.zeros(len(SHADOW_JOINT_NAMES))
    for joint, value in prior.items():
        q[SHADOW_JOINT_NAMES.index(joint)] = value
    for f in ("FF", "MF", "RF", "LF"):
        j1, j2 = SHADOW_JOINT_NAMES.index(f"{f}J1"), SHADOW_JOINT_NAMES.index(f"{f}J2")
        q[j1] = coupling_ratio * q[j2]
    return q


def generate(
    sizes_per_class: int = 5,
    experimenters: int = 3,
    seed: int = 0,
    classes=None,
    shapes=CLASS_SHAPES,
    attempts: int = 4,
    coupling_ratio: float = 1.0,
    progress=None,
) -> tuple[GraspRecords, list[dict]]:
    """Solve the synthetic grasps; returns the kept grasps and a log of every case."""
    rng = np.random.default_rng(seed)
    classes = [grasp_info(c).grasp_class for c in (classes or list(GRASP_CLASSES))]
    styles = {f"synth{e + 1}": rng.normal(scale=0.06, size=len(SHADOW_JOINT_NAMES))
              for e in range(experimenters)}
    clock = datetime(2012, 2, 14, 9, 0, tzinfo=UTC)
    rows: dict[str, list] = {k: [] for k in ("q", "cls", "shape", "dims", "who", "time")}
    log = []
    for cls in classes:
        lo, hi = grasp_info(cls).size_range_m
        prior0 = posture_prior(cls, coupling_ratio)
        for shape in shapes:
            for size in np.linspace(lo, hi, sizes_per_class):
                dims = object_dims_for(shape, size, cls)
                gk = GraspKinematics(coupling_ratio, shape=shape, dims=dims)
                for who, style in styles.items():
                    kept = None
                    for _attempt in range(attempts):
                        # Retries widen the draw (0.03, 0.08, 0.13 ... rad) to leave a bad basin.
                        prior = prior0 + style + rng.normal(scale=0.03 + 0.05 * _attempt,
                                                            size=prior0.size)
                        sol = gk.solve_grasp(cls, shape, dims, prior, rng=rng, target_jitter=0.002,
                                             centre_prior_weight=100.0)
                        if sol.success and sol.contact_error < 1e-3:
                            kept = sol
                            break
                    log.append(dict(grasp_class=cls.value, shape=shape, size=float(size),
                                    experimenter=who, success=kept is not None))
                    if progress:
                        progress(log[-1])
                    if kept is None:
                        continue
                    # Teaching time: the report's Fig. 5 shows seconds to minutes per grasp.
                    clock += timedelta(seconds=float(rng.lognormal(np.log(20.0), 0.6)))
                    rows["q"].append(kept.q)
                    rows["cls"].append(cls)
                    rows["shape"].append(shape)
                    rows["dims"].append(dims)
                    rows["who"].append(who)
                    rows["time"].append(clock)
    records = GraspRecords(
        np.array(rows["q"]).reshape(-1, len(SHADOW_JOINT_NAMES)), rows["cls"], rows["shape"],
        rows["dims"], rows["who"], rows["time"],
    )
    return records, log


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--out", type=Path, default=DATA_FILE)
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--sizes", type=int, default=5)
    parser.add_argument("--experimenters", type=int, default=3)
    args = parser.parse_args(argv)

    def show(entry):
        print(f"{entry['grasp_class']:20s} {entry['shape']:8s} {entry['size']:.4f} "
              f"{entry['experimenter']} {'ok' if entry['success'] else 'FAILED'}", flush=True)

    records, log = generate(args.sizes, args.experimenters, args.seed, progress=show)
    args.out.parent.mkdir(parents=True, exist_ok=True)
    save_grasps(args.out, records)
    print(f"wrote {len(records)} grasps ({len(log)} cases) to {args.out}")
    for cls in GRASP_CLASSES.values():
        cases = [e for e in log if e["grasp_class"] == cls.name]
        ok = sum(e["success"] for e in cases)
        print(f"{cls.name:20s} kept {ok}/{len(cases)}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
