"""Device profiles of the report's instrumented objects (section 2.4, Figure 2).

A :class:`DeviceProfile` says what a consumer accelerometer does to the
proper acceleration it feels: it samples at ``rate_hz`` and holds the sample
(zero-order hold), adds a constant bias and white noise, clips at
``range_g`` (saturation) and rounds to ``bits`` of signed resolution over
``[-range_g, +range_g)``. One count is ``lsb = 2 * range_g * g0 / 2**bits``
m/s^2 and readings are integers in ``[-2**(bits-1), 2**(bits-1) - 1]``.

The noise is seeded and depends only on ``(seed, sample index)``, so a run
is reproducible and a reset replays the same noise; the bias is drawn once
per seed from ``bias_std_g`` (set it to zero, or give ``bias_g``, for a
calibrated device). Sources of each number are in the comments next to the
profiles; figures a datasheet gives as a range are set at a typical value.
"""

from __future__ import annotations

import dataclasses as dc
import math
from functools import lru_cache

import numpy as np

__all__ = [
    "STANDARD_GRAVITY",
    "DeviceProfile",
    "PROFILES",
    "get_profile",
    "to_counts",
    "counts_to_acceleration",
    "sample_noise",
    "device_bias",
]

#: m/s^2 per g (the ISO 80000-3 standard gravity that datasheets quote g in).
STANDARD_GRAVITY = 9.80665


#: Accepted ranges. Accelerometers span about +-1 g (tilt sensors) to a few
#: hundred g (shock sensors), sampled from a few Hz to tens of kHz; outside
#: that a value is a typo (1e-300 g: every reading saturates; 1e300 Hz: a
#: sample period Drake cannot schedule).
PROFILE_LIMITS = {"range_g": (0.01, 1000.0), "rate_hz": (0.1, 100_000.0)}


@dc.dataclass(frozen=True)
class DeviceProfile:
    """What a device does to the acceleration it feels (see the module doc).

    Attributes:
        name: the profile's key in :data:`PROFILES`.
        range_g: full scale (g): readings saturate at +-range_g.
        bits: signed resolution over the full scale (2..32).
        rate_hz: sample rate (Hz); the output is held between samples.
        noise_std_g: white-noise standard deviation per sample and axis (g).
        bias_std_g: standard deviation of the per-device constant bias (g).
        bias_g: a fixed bias (g, 3 axes) instead of a drawn one (calibration).
        description: what the device is, for tables and plots.
    """

    name: str
    range_g: float
    bits: int
    rate_hz: float
    noise_std_g: float = 0.0
    bias_std_g: float = 0.0
    bias_g: tuple[float, float, float] | None = None
    description: str = ""

    def __post_init__(self):
        for field in ("range_g", "rate_hz"):
            value = getattr(self, field)
            if isinstance(value, bool) or not isinstance(value, int | float | np.number) \
                    or not math.isfinite(value) or value <= 0:
                raise ValueError(f"{field} must be a finite number > 0, got {value!r}")
            low, high = PROFILE_LIMITS[field]
            if not low <= value <= high:
                raise ValueError(f"{field} must be in [{low:g}, {high:g}], got {value!r}")
            object.__setattr__(self, field, float(value))
        if isinstance(self.bits, bool) or not isinstance(self.bits, int | np.integer) \
                or not 2 <= self.bits <= 32:
            raise ValueError(f"bits must be an integer in [2, 32], got {self.bits!r}")
        object.__setattr__(self, "bits", int(self.bits))
        for field in ("noise_std_g", "bias_std_g"):
            value = getattr(self, field)
            if isinstance(value, bool) or not isinstance(value, int | float | np.number) \
                    or not math.isfinite(value) or value < 0:
                raise ValueError(f"{field} must be a finite number >= 0, got {value!r}")
            object.__setattr__(self, field, float(value))
        if self.bias_g is not None:
            bias = np.asarray(self.bias_g, dtype=float).ravel()
            if bias.shape != (3,) or not np.all(np.isfinite(bias)):
                raise ValueError(f"bias_g: expected 3 finite values (g), got {self.bias_g!r}")
            object.__setattr__(self, "bias_g", tuple(float(b) for b in bias))

    @property
    def period(self) -> float:
        """Sample period (s)."""
        return 1.0 / self.rate_hz

    @property
    def lsb(self) -> float:
        """One count in m/s^2."""
        return 2.0 * self.range_g * STANDARD_GRAVITY / 2 ** self.bits

    @property
    def counts_per_g(self) -> float:
        return STANDARD_GRAVITY / self.lsb

    @property
    def count_limits(self) -> tuple[int, int]:
        """Smallest and largest reading (counts)."""
        half = 2 ** (self.bits - 1)
        return -half, half - 1

    def replace(self, **changes) -> DeviceProfile:
        """A copy with some fields changed (validated again)."""
        return dc.replace(self, **changes)


# Sources (checked against the datasheets of the sensing chips these devices use):
#
# JoyWarrior24F14 (Code Mercenaries, www.codemercs.com): the report's device, "14-bit
#   values at a sample rate of up to 125 Hz" with user-selectable sensitivity (report
#   section 2.4.3). Its sensor is a Bosch BMA180 (JoyWarrior24F14 datasheet): ranges
#   +-1/1.5/2/3/4/8/16 g, 14 bit, so at +-2 g one count is 0.25 mg (4096 counts/g);
#   BMA180 noise density 150 ug/sqrt(Hz) (low-noise mode) over the ~62 Hz bandwidth of a
#   125 Hz output: 1.2 mg RMS; zero-g offset after calibration about +-5 mg (the report
#   recommends "a quick calibration of the device").
# Wiimote (Nintendo RVL-CNT-01): ADXL330 (Analog Devices) accelerometer, +-3 g minimum
#   full scale, noise density 280 ug/sqrt(Hz) (x, y; 350 for z) over its ~50 Hz report
#   bandwidth: ~2 mg RMS. Read over Bluetooth at 100 reports/s with 10 bits on x and 9+1
#   on y, z (wiibrew.org "Wiimote#Accelerometer"); the factory calibration in its
#   EEPROM leaves a zero-g offset of ~+-30 mg uncalibrated (ADXL330: +-150 mg
#   before trim).
# Nunchuk (Nintendo RVL-004): ST LIS3L02AL, +-2 g, 10-bit readings (wiibrew.org
#   "Wiimote/Extension Controllers/Nunchuck"), reported through the Wiimote at 100 Hz;
#   noise density 50 ug/sqrt(Hz): ~0.4 mg RMS, dominated by the 10-bit step (3.9 mg).
# Sixaxis (Sony CECHZC1): 10-bit accelerometer readings at ~113 counts/g around 512
#   (Linux hid-sony and the ROS ps3joy driver read them as 10-bit values), so about
#   +-4.5 g of code range; USB/Bluetooth HID reports at 100 Hz (ps3joy); noise taken as
#   the Wiimote's (its chip's datasheet is not public).
PROFILES: dict[str, DeviceProfile] = {
    profile.name: profile
    for profile in (
        DeviceProfile("joywarrior24f14", range_g=2.0, bits=14, rate_hz=125.0,
                      noise_std_g=0.0012, bias_std_g=0.005,
                      description="Code Mercenaries JoyWarrior24F14 (BMA180, +-2 g, 14 bit)"),
        DeviceProfile("wiimote", range_g=3.0, bits=10, rate_hz=100.0,
                      noise_std_g=0.002, bias_std_g=0.03,
                      description="Nintendo Wiimote (ADXL330, +-3 g, 10 bit)"),
        DeviceProfile("nunchuk", range_g=2.0, bits=10, rate_hz=100.0,
                      noise_std_g=0.0004, bias_std_g=0.03,
                      description="Nintendo Nunchuk (LIS3L02AL, +-2 g, 10 bit)"),
        DeviceProfile("sixaxis", range_g=4.5, bits=10, rate_hz=100.0,
                      noise_std_g=0.002, bias_std_g=0.03,
                      description="Sony Sixaxis (10 bit, ~113 counts/g)"),
        # An ideal sensor: for tests and for separating the estimator's error from the
        # device's. 24 bits over +-16 g is 2 ug per count.
        DeviceProfile("ideal", range_g=16.0, bits=24, rate_hz=1000.0,
                      description="ideal accelerometer (no noise or bias, 24 bit, 1 kHz)"),
    )
}


def get_profile(device: str | DeviceProfile) -> DeviceProfile:
    """The profile named ``device`` (or ``device`` itself if it is one)."""
    if isinstance(device, DeviceProfile):
        return device
    if not isinstance(device, str):
        raise TypeError(f"device must be a profile name (str), got {type(device).__name__}")
    if device not in PROFILES:
        raise ValueError(f"device: unknown accelerometer {device!r}; "
                         f"expected one of {sorted(PROFILES)}")
    return PROFILES[device]


def to_counts(a: np.ndarray, profile: DeviceProfile) -> np.ndarray:
    """Device counts of the acceleration ``a`` (m/s^2, any shape): round to the
    nearest count, then saturate at the profile's count limits."""
    lo, hi = profile.count_limits
    counts = np.rint(np.asarray(a, dtype=float) / profile.lsb)
    return np.clip(counts, lo, hi)


def counts_to_acceleration(counts: np.ndarray, profile: DeviceProfile) -> np.ndarray:
    """m/s^2 of device counts."""
    return np.asarray(counts, dtype=float) * profile.lsb


#: Noise is drawn in blocks of this many samples (one generator per block, cached).
_NOISE_BLOCK = 1024


@lru_cache(maxsize=64)
def _noise_block(seed: int, block: int) -> np.ndarray:
    return np.random.default_rng((seed, 1, block)).standard_normal((_NOISE_BLOCK, 3))


def sample_noise(profile: DeviceProfile, seed: int, index: int) -> np.ndarray:
    """The noise (m/s^2, 3 axes) of sample ``index``: a function of the seed and the
    index only (standard normals drawn in cached blocks of 1024 samples per
    ``(seed, block)``), so runs and resets replay it exactly."""
    if profile.noise_std_g == 0.0:
        return np.zeros(3)
    block, row = divmod(int(index), _NOISE_BLOCK)
    return _noise_block(int(seed), block)[row] * (profile.noise_std_g * STANDARD_GRAVITY)


def device_bias(profile: DeviceProfile, seed: int) -> np.ndarray:
    """The device's constant bias (m/s^2, 3 axes): ``bias_g`` if given, else drawn
    from ``bias_std_g`` with ``seed``."""
    if profile.bias_g is not None:
        return np.asarray(profile.bias_g) * STANDARD_GRAVITY
    if profile.bias_std_g == 0.0:
        return np.zeros(3)
    rng = np.random.default_rng((int(seed), 0))
    return rng.normal(scale=profile.bias_std_g * STANDARD_GRAVITY, size=3)
