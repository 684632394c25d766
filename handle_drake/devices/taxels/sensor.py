"""The taxel arrays as Drake systems: the simulated sensor, a recorded stream's playback
and the Meshcat drawing.

:class:`TaxelArray` ports:

- input ``contact_results`` (abstract ``ContactResults``, the plant's).
- input ``body_poses`` (abstract ``vector<RigidTransform>``, the plant's ``X_WB``).
- output ``taxels`` (sum of the pads' cells, Pa): each cell's pressure as the device
  reads it (noise, saturation and quantisation of its profile), sampled at the first
  pad's ``rate_hz`` and held; pads in :func:`~.pads.shadow_pads` order, cells row-major
  (row 0 nearest the pad's proximal end, column 0 at the pad's -x side).
- output ``counts`` (same size): the readings in device counts.
- output ``forces`` (same size, N): each cell's ideal normal force (no noise, not
  sampled; ground truth for tests).

:class:`TaxelPlayback` ports: output ``taxels`` (Pa): the recorded frame at or before
the current time (zero-order hold), from an ``.npz`` file with ``times`` (N,) and
``taxels`` (N, cells) (what :func:`save_recording` writes).

:class:`TaxelMeshcat` ports: input ``taxels`` (Pa), input ``body_poses``: draws each
cell as a thin box on its pad, coloured from white (0) to red (the profile's range).
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
from pydrake.common.value import AbstractValue
from pydrake.geometry import Box, Rgba
from pydrake.math import RigidTransform
from pydrake.multibody.plant import ContactResults
from pydrake.systems.framework import BasicVector, EventStatus, LeafSystem

from handle_drake.devices.taxels.pads import Pad, PadForces

__all__ = ["TaxelArray", "TaxelPlayback", "TaxelMeshcat", "save_recording", "load_recording"]


class TaxelArray(LeafSystem):
    """The simulated taxel arrays of ``pads`` (see the module doc for the ports).

    Args:
        plant: the finalized plant whose contact results the sensor reads.
        pads: from :func:`~.pads.shadow_pads`.
        noise: False leaves out the noise (still sampled, saturated and quantised).
        seed: the noise seed; sample ``k``'s noise depends only on ``(seed, k)``.
    """

    def __init__(self, plant, pads: list[Pad], noise: bool = True, seed: int = 0):
        super().__init__()
        if not pads:
            raise ValueError("taxels: expected at least one pad, got none")
        self._pads = list(pads)
        self._forces = PadForces(plant, self._pads)
        n = self._forces.size
        self._area = np.concatenate([np.full(p.cells, p.profile.cell_area) for p in pads])
        self._lsb = np.concatenate([np.full(p.cells, p.profile.lsb) for p in pads])
        self._range = np.concatenate([np.full(p.cells, p.profile.range_pa) for p in pads])
        self._noise = np.concatenate([np.full(p.cells, p.profile.noise_std_pa) for p in pads]) \
            if noise else np.zeros(n)
        self._seed = int(seed)
        self._noisy = bool(np.any(self._noise))
        self._rng = np.random.Generator(np.random.Philox(key=self._seed % 2 ** 64))
        self._period = pads[0].profile.period
        self._contacts = self.DeclareAbstractInputPort(
            "contact_results", AbstractValue.Make(ContactResults()))
        self._poses = self.DeclareAbstractInputPort(
            "body_poses", AbstractValue.Make([RigidTransform()]))
        self._state = self.DeclareDiscreteState(n)
        self.DeclarePeriodicDiscreteUpdateEvent(self._period, 0.0, self._sample)
        # a caller may also take a sample now (CalcForcedDiscreteVariableUpdate)
        self.DeclareForcedDiscreteUpdateEvent(self._sample)
        self.DeclareVectorOutputPort(
            "taxels", n, lambda c, o: o.SetFromVector(
                c.get_discrete_state(self._state).value() * self._lsb),
            {self.xd_ticket()})
        self.DeclareVectorOutputPort(
            "counts", n, lambda c, o: o.SetFromVector(c.get_discrete_state(self._state).value()),
            {self.xd_ticket()})
        self.DeclareVectorOutputPort("forces", n, self._calc_forces)

    @property
    def pads(self) -> list[Pad]:
        return list(self._pads)

    def get_contact_results_input_port(self):
        return self._contacts

    def get_body_poses_input_port(self):
        return self._poses

    def _ideal(self, context) -> np.ndarray:
        # the body poses only when a contact touches a padded body
        return self._forces(self._contacts.Eval(context), lambda: self._poses.Eval(context))

    def _calc_forces(self, context, out: BasicVector):
        out.SetFromVector(self._ideal(context))

    def _sample(self, context, state):
        pressure = self._ideal(context) / self._area
        k = int(round(context.get_time() / self._period))
        if self._noisy:
            pressure += self._normal(k) * self._noise
        counts = np.rint(np.minimum(np.maximum(pressure, 0.0), self._range) / self._lsb)
        state.set_value(self._state, counts)
        return EventStatus.Succeeded()

    def _normal(self, k: int) -> np.ndarray:
        """Sample ``k``'s standard normal noise: Philox's stream at key ``seed``, counter
        ``k`` (depends only on ``(seed, k)``)."""
        bits = self._rng.bit_generator
        state = bits.state
        state["state"]["counter"][:] = (k, 0, 0, 0)
        state["buffer_pos"] = 4  # the buffer is used up: the next draw starts at counter k
        state["has_uint32"] = 0
        bits.state = state
        return self._rng.standard_normal(self._area.size)


def save_recording(path, times, taxels) -> Path:
    """Writes a taxel stream (``times`` (N,) s, ``taxels`` (N, cells) Pa) as ``.npz``."""
    path = Path(path)
    np.savez(path, times=np.asarray(times, float), taxels=np.asarray(taxels, float))
    return path


def load_recording(path, cells: int | None = None) -> tuple[np.ndarray, np.ndarray]:
    """``(times, taxels)`` of a recording; ValueError naming the file when it is not one."""
    path = Path(path)
    if not path.is_file():
        raise FileNotFoundError(f"taxels.recording: no such file {str(path)!r}")
    try:
        with np.load(path, allow_pickle=False) as data:
            times, taxels = np.asarray(data["times"], float), np.asarray(data["taxels"], float)
    except (KeyError, ValueError, OSError) as error:
        raise ValueError(f"taxels.recording: {str(path)!r} is not a taxel recording (.npz with "
                         f"times and taxels): {error}") from None
    if times.ndim != 1 or taxels.ndim != 2 or len(times) != len(taxels) or len(times) == 0:
        raise ValueError(f"taxels.recording: {str(path)!r}: expected times (N,) and taxels "
                         f"(N, cells), got {times.shape} and {taxels.shape}")
    if cells is not None and taxels.shape[1] != cells:
        raise ValueError(f"taxels.recording: {str(path)!r}: expected {cells} cells per frame, "
                         f"got {taxels.shape[1]}")
    if not (np.all(np.isfinite(times)) and np.all(np.diff(times) > 0)
            and np.all(np.isfinite(taxels))):
        raise ValueError(f"taxels.recording: {str(path)!r}: times must increase and all values "
                         "be finite")
    return times, taxels


class TaxelPlayback(LeafSystem):
    """A recorded taxel stream as the ``taxels`` output (see the module doc)."""

    def __init__(self, times, taxels):
        super().__init__()
        self._times = np.asarray(times, float)
        self._frames = np.asarray(taxels, float)
        self.DeclareVectorOutputPort("taxels", self._frames.shape[1], self._calc)

    def _calc(self, context, out: BasicVector):
        i = int(np.searchsorted(self._times, context.get_time(), side="right")) - 1
        out.SetFromVector(self._frames[max(i, 0)] if i >= 0 else np.zeros(self._frames.shape[1]))


class TaxelMeshcat(LeafSystem):
    """Draws the taxel images into Meshcat at ``period`` (see the module doc)."""

    def __init__(self, meshcat, pads: list[Pad], period: float = 0.05, prefix: str = "taxels"):
        super().__init__()
        self._meshcat = meshcat
        self._pads = list(pads)
        self._prefix = prefix
        n = sum(p.cells for p in pads)
        self._range = np.concatenate([np.full(p.cells, p.profile.range_pa) for p in pads])
        self._taxels = self.DeclareVectorInputPort("taxels", n)
        self._poses = self.DeclareAbstractInputPort(
            "body_poses", AbstractValue.Make([RigidTransform()]))
        self._paths = []
        for pad in self._pads:
            profile = pad.profile
            box = Box(profile.pitch_col * 0.9, profile.pitch_row * 0.9, 0.0006)
            for cell, (u, v) in enumerate(profile.cell_centres()):
                path = f"{prefix}/{pad.name}/{cell}"
                meshcat.SetObject(path, box, Rgba(1, 1, 1, 0.9))
                meshcat.SetTransform(path, RigidTransform([u, v, 0.0004]))
                self._paths.append(path)
        self.DeclarePeriodicPublishEvent(period, 0.0, self._publish)

    def _publish(self, context):
        poses = self._poses.Eval(context)
        for pad in self._pads:
            self._meshcat.SetTransform(f"{self._prefix}/{pad.name}",
                                       poses[pad.body_index] @ pad.X_BP)
        level = np.clip(self._taxels.Eval(context) / self._range, 0.0, 1.0)
        for path, x in zip(self._paths, level, strict=True):
            self._meshcat.SetProperty(path, "color", [1.0, 1.0 - x, 1.0 - x, 0.9])
        return EventStatus.Succeeded()
