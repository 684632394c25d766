"""The scenario field that gives the hand taxel arrays (``hand.taxels``).

No ``from __future__ import annotations`` here: Drake's YAML reader needs real types.

.. code-block:: yaml

    hand:
      kind: shadow
      taxels:
        profile: pad4x4      # a profile of handle_drake.devices.taxels.PROFILES (distal pads)
        palm: palm6x6        # the palm's profile; "" = no palm pad
        skin: skin5mm        # the proximal and middle phalanges' skins; "" = none
        # noise: false       (still sampled, saturated and quantised)
        # rate_hz: 50        (the sample rate instead of the profile's)
        # seed: 3            (default: the scenario's random_seed)
        # estimator: true    (the station also exports object.pose_estimated)
        # recording: run.npz (hardware=True: hand.taxels plays this recorded stream)
"""

import dataclasses as dc

from handle_drake.devices.taxels.profiles import get_profile

__all__ = ["TaxelConfig"]


@dc.dataclass
class TaxelConfig:
    profile: str = "pad4x4"
    palm: str = "palm6x6"
    skin: str = "skin5mm"
    noise: bool = True
    # the sample rate (Hz) instead of the profile's (pads and palm); None keeps it. Each
    # sample evaluates the plant's contact results: the station's main cost of taxels.
    rate_hz: float | None = None
    seed: int | None = None
    estimator: bool = False
    # the estimator's update rate (Hz) and prior (the object's pose before the grasp,
    # the scenario's X_WO, believed within these standard deviations)
    estimator_rate_hz: float = 20.0
    prior_position_std: float = 0.01
    prior_angle_std: float = 0.2
    recording: str = ""

    def validate(self) -> None:
        """Raises ValueError naming the field (prefix ``hand.taxels.`` is the caller's)."""
        for field in ("profile", "palm", "skin", "recording"):
            if not isinstance(getattr(self, field), str):
                raise ValueError(f"{field}: expected a string, got {getattr(self, field)!r}")
        try:
            get_profile(self.profile)
        except ValueError as error:
            raise ValueError(f"profile: {error}") from None
        for field in ("palm", "skin"):
            if getattr(self, field):
                try:
                    get_profile(getattr(self, field))
                except ValueError as error:
                    raise ValueError(f"{field}: {error}") from None
        if self.rate_hz is not None:
            try:
                get_profile(self.profile).replace(rate_hz=self.rate_hz)
            except ValueError as error:
                raise ValueError(str(error)) from None
        for field, (low, high) in (("estimator_rate_hz", (1.0, 1000.0)),
                                   ("prior_position_std", (1e-4, 1.0)),
                                   ("prior_angle_std", (1e-3, 3.15))):
            value = getattr(self, field)
            if isinstance(value, bool) or not isinstance(value, int | float) \
                    or not low <= value <= high:
                raise ValueError(f"{field}: expected a number in [{low:g}, {high:g}], "
                                 f"got {value!r}")
