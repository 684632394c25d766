"""The scenario field that attaches an accelerometer to the object.

No ``from __future__ import annotations`` here: Drake's YAML reader needs real
types (see ``handle_drake.scenario``).

.. code-block:: yaml

    object:
      kind: cylinder
      accelerometer:
        device: joywarrior24f14      # a profile of handle_drake.instruments.PROFILES
        X_OS: {translation: [0, 0, 0.05], rotation: !Rpy {deg: [0, 0, 90]}}
        # range_g: 4.0  bits: 12  rate_hz: 50   (override the profile)
        # noise: false                (no noise and bias; still sampled and quantised)
        # calibrated: false           (raw readings: no six-position calibration first)
        # seed: 3                     (default: the scenario's random_seed)
        # estimators: {free_fall_threshold: 0.25}
        # evdev_device: /dev/input/event5   (hardware=True: the real device)

``X_OS`` is the sensor frame S in the object frame O; left out, it is the
catalogue's named sensor frame of an instrumented object (JoyWarrior, Wiimote,
...), else the object's origin, or, where the origin is off the object (a mug's
is in its cavity, an L bracket's beside its arms), the surface point nearest to
it (``instruments.accelerometer.default_sensor_pose``). ``device`` left out is
the object's own device for an instrumented object, else the JoyWarrior.
"""

import dataclasses as dc
import math
import numbers

from pydrake.common.schema import Transform

__all__ = ["AccelerometerConfig", "ESTIMATOR_MAXIMA"]

#: The largest value of each estimator threshold that still means something (all > 0):
#: durations (s) up to a minute, magnitudes (g) up to 1 g for the free-fall threshold
#: (at or above 1 g an object at rest is "falling") and 16 g (the largest accelerometer
#: range) for the others, angles (rad) up to pi, the command's stillness up to 1 rad or m.
ESTIMATOR_MAXIMA = {
    "window": 60.0, "rest_window": 60.0, "free_fall_duration": 60.0, "slip_duration": 60.0,
    "settle_time": 60.0, "free_fall_threshold": 1.0, "rest_norm_tol": 16.0,
    "rest_std_tol": 16.0, "slip_norm_tol": 16.0, "rest_angle_tol": math.pi,
    "slip_angle_tol": math.pi, "still_tol": 1.0,
}


@dc.dataclass
class AccelerometerConfig:
    device: str = ""  # profile name; "" = the object's own device (or joywarrior24f14)
    X_OS: Transform | None = None  # sensor pose in the object frame; None = named frame
    range_g: float | None = None  # overrides of the profile
    bits: int | None = None
    rate_hz: float | None = None
    noise: bool = True  # False: no noise, no bias
    # True: the six-position calibration from the device's own rest readings first
    # (instruments.calibration), as a real experiment does; False: raw readings.
    calibrated: bool = True
    seed: int | None = None  # None: the scenario's random_seed
    # EstimatorParams fields by name (window, free_fall_threshold, slip_angle_tol, ...).
    estimators: dict[str, float] = dc.field(default_factory=dict)
    # hardware=True: the evdev device (path /dev/input/eventN, or a name to look for).
    evdev_device: str = ""

    def profile(self, kind: str | None = None):
        """The device profile with this config's overrides (validated)."""
        from handle_drake.instruments.catalogue import DEVICE_OBJECTS
        from handle_drake.instruments.profiles import get_profile

        name = self.device or (DEVICE_OBJECTS[kind].device if kind in DEVICE_OBJECTS
                               else "joywarrior24f14")
        profile = get_profile(name)
        changes = {k: getattr(self, k) for k in ("range_g", "bits", "rate_hz")
                   if getattr(self, k) is not None}
        if not self.noise:
            changes.update(noise_std_g=0.0, bias_std_g=0.0, bias_g=None)
        return profile.replace(**changes) if changes else profile

    def estimator_params(self, kind: str | None = None, calibrated: bool | None = None):
        """The estimators' thresholds: those given in ``estimators``, the others at least
        what the device's noise and (residual) bias need
        (:func:`~handle_drake.instruments.calibration.device_estimator_params`).
        ``calibrated``: whether the readings are (default: ``self.calibrated``)."""
        from handle_drake.instruments.calibration import device_estimator_params
        from handle_drake.instruments.estimators import EstimatorParams

        known = {f.name for f in dc.fields(EstimatorParams)}
        for key in self.estimators:
            if key not in known:
                raise ValueError(f"estimators: unknown parameter {key!r}; "
                                 f"expected some of {sorted(known)}")
            value, high = self.estimators[key], ESTIMATOR_MAXIMA.get(key)
            if high is not None and isinstance(value, numbers.Real) \
                    and not isinstance(value, bool) and value > high:
                raise ValueError(f"estimators.{key}: expected a value in (0, {high:g}], "
                                 f"got {value!r}")
        return device_estimator_params(self.profile(kind),
                                       self.calibrated if calibrated is None else calibrated,
                                       self.estimators)

    def calibration(self, kind: str | None, seed: int):
        """The device's six-position calibration from its own rest readings, or None
        (``calibrated: false``, or a device without bias and noise)."""
        from handle_drake.instruments.calibration import calibrate_device

        profile = self.profile(kind)
        if not self.calibrated or (profile.noise_std_g == 0 and profile.bias_std_g == 0
                                   and profile.bias_g is None):
            return None
        return calibrate_device(profile, seed)

    def validate(self, kind: str) -> None:
        """Raises ValueError naming the field (without the ``object.accelerometer.`` prefix)."""
        for field in ("range_g", "rate_hz"):
            value = getattr(self, field)
            if value is not None and not (math.isfinite(value) and value > 0):
                raise ValueError(f"{field} must be a finite number > 0, got {value!r}")
        if self.bits is not None and not 2 <= self.bits <= 32:
            raise ValueError(f"bits must be an integer in [2, 32], got {self.bits!r}")
        if self.seed is not None and not 0 <= self.seed < 2**32:
            raise ValueError(f"seed: expected an integer in [0, 2**32), got {self.seed!r}")
        self.profile(kind)
        self.estimator_params(kind)
