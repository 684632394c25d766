"""The ``!Arm`` mount of a scenario: the hand bolted to a robot arm's flange.

Kept free of pydrake systems so that :mod:`handle_drake.scenario` can import it.

.. code-block:: yaml

    hand:
      kind: shadow
      mount: !Arm
        kind: pa10
        X_WB: {translation: [-0.55, 0, -0.10]}     # the arm's base plate in world
        initial_position: [0, 0.6, 1.6, 0, 0.9, 0]  # rad, S1 S2 E1 E2 W1 W2
        X_FH: {rotation: !Rpy {deg: [0, 0, 0]}}     # hand base in the flange frame
"""

import dataclasses as dc
import math

from pydrake.common.schema import Transform

__all__ = ["Arm", "validate_arm"]


@dc.dataclass
class Arm:
    """The hand on a robot arm (see :mod:`handle_drake.arm`).

    ``X_WB`` is the pose of the arm's base plate in world; ``X_FH`` the pose of
    the hand's base body in the arm's flange frame (the adapter plate);
    ``initial_position`` the arm's joint positions (rad, the arm's joint
    order; empty: all 0, straight up) at the start, held by the driver until
    ``arm.position`` says otherwise. ``kp``/``kd`` (N m/rad, N m s/rad) are the
    joint servo gains (empty: the arm's defaults). The driver compensates
    gravity, as a real arm's servo controller does: gravity is off for the arm
    and the hand (it still acts on the objects).
    """

    kind: str = "pa10"
    X_WB: Transform = dc.field(default_factory=Transform)
    X_FH: Transform = dc.field(default_factory=Transform)
    initial_position: list[float] = dc.field(default_factory=list)
    kp: list[float] = dc.field(default_factory=list)
    kd: list[float] = dc.field(default_factory=list)
    # Period (s) at which the arm command is sampled and rate limited to the
    # joints' speed limits (the PA10 servo's command rate is 2-10 ms).
    control_period: float = 0.005


def validate_arm(arm: Arm, error) -> None:
    """Checks ``hand.mount`` when it is an :class:`Arm`; raises ``error(message)``."""
    from handle_drake.arm.model import ARM_SPECS

    if arm.kind not in ARM_SPECS:
        raise error(f"hand.mount.kind: unknown arm {arm.kind!r}; expected one of "
                    f"{sorted(ARM_SPECS)}")
    spec = ARM_SPECS[arm.kind]
    n = len(spec.joint_names)
    for name in ("initial_position", "kp", "kd"):
        values = getattr(arm, name)
        if not values:
            continue
        if len(values) != n or not all(isinstance(v, int | float) and math.isfinite(v)
                                       for v in values):
            raise error(f"hand.mount.{name}: expected {n} finite values "
                        f"({', '.join(spec.joint_names)}), got {list(values)[:8]}")
        if name != "initial_position" and any(v <= 0 for v in values):
            raise error(f"hand.mount.{name}: expected values > 0, got {list(values)}")
    # An empty initial_position (the default, all 0) has nothing to check.
    for i, (q, lo, hi) in enumerate(zip(arm.initial_position, spec.lower, spec.upper,
                                        strict=False)):
        if not lo <= q <= hi:
            raise error(f"hand.mount.initial_position[{i}] ({spec.joint_names[i]}): "
                        f"{q:g} rad is outside the joint's range [{lo:.4f}, {hi:.4f}]")
    for name in ("X_WB", "X_FH"):
        transform = getattr(arm, name)
        if not transform.IsDeterministic():
            raise error(f"hand.mount.{name}: expected a deterministic pose, got a random one")
    if not (math.isfinite(arm.control_period) and 0 < arm.control_period <= 0.1):
        raise error(f"hand.mount.control_period: expected a period in (0, 0.1] s, "
                    f"got {arm.control_period!r}")
