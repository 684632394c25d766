"""The station's port contract: the names both branches (simulation, CAN hardware) export.

One place for them: :func:`~handle_drake.station.MakeHandStation` exports them
from the simulated driver and sensors, :func:`~handle_drake.station.MakeHardwareStation`
(through :func:`~handle_drake.devices.can_hand.driver.AddCanHandDriver`) from the CAN
hand's proxy, each in a loop, so every controller, trial and notebook is
written once. Port names are ``<model instance>.<signal>``.
"""

__all__ = ["HAND", "HAND_COMMAND", "HAND_SIGNALS", "WRIST"]

HAND = "hand"  # the hand's model instance, and the prefix of its ports
WRIST = "wrist"  # the floating wrist (simulation only)

#: ``hand.position`` (in, nu rad, command order).
HAND_COMMAND = "position"

#: ``hand.<signal>`` outputs of both branches: the rate-limited command (nu, rad),
#: the measured joint positions (nq, rad), the estimated velocities (nq, rad/s),
#: positions then velocities (2 nq), the fingertip normal forces (N).
HAND_SIGNALS = ("position_commanded", "position_measured", "velocity_estimated",
                "state_estimated", "tactile")
