"""The Figure 8 experiments: in-hand rotations measured by the object itself.

Report section 3.4, Figure 8: the Shadow hand rotates the Wiimote held in a
parallel-extension grasp and the JoyWarrior held in a tripod grasp. Here:

1. the grasp planner (``handle_drake.grasp``, as ``handle-drake grasp --class
   ...``) plans the class on a box of the device's outer size resting on the
   table (the JoyWarrior stands on its 37 x 25 mm side: a 25 mm grasp width;
   the Wiimote lies flat: 36.2 mm across its width); its keyframes reach,
   close and lift the device;
2. the scripted wrist then turns the device about its own centre by world
   rotations (``ROTATIONS_DEG``), holding still after each move;
3. the hand opens (back to the pre-shape) and the device falls to the table.

The device's accelerometer (its catalogue sensor frame and profile, seeded
noise and bias) feeds the station's estimators; Drake's loggers record the
estimates, the flags and the true sensor orientation from the plant right
after each device sample (a ``ZeroOrderHold`` with the device's period and a
0.2 ms offset, logged by a ``VectorLogSink``: the figures are bit-identical to
the former list recorder's). Reported (:class:`Figure8Result.summary`): roll and
pitch errors in degrees (RMS and max) over the at-rest phases (each hold after
its first ``REST_SETTLE`` s) and while moving; false free-fall and slip alarms
while the grasp holds (lift done to the open command); the free-fall
detection delay, from the start of the fall to the detector's flag, where the
fall starts when an ideal sensor (Drake's ``Accelerometer`` sampled every
``RELEASE_PERIOD`` s) goes below the free-fall threshold for good (until the
flag).

``handle-drake instruments`` runs them; the scenario files
``diagrams/instrumented_<device>_<class>.yaml`` (:func:`write_scenarios`) run
with ``handle-drake simulate``.
"""

from __future__ import annotations

import dataclasses as dc
import math
from pathlib import Path

import numpy as np
from pydrake.common.schema import Transform
from pydrake.common.value import AbstractValue
from pydrake.math import RigidTransform, RollPitchYaw, RotationMatrix
from pydrake.systems.framework import LeafSystem
from pydrake.systems.primitives import (
    LogVectorOutput,
    Multiplexer,
    VectorLogSink,
    ZeroOrderHold,
)

from handle_drake.devices.accelerometer.config import AccelerometerConfig
from handle_drake.devices.accelerometer.estimators import angle_difference, true_roll_pitch
from handle_drake.devices.accelerometer.wiring import instrument_X_OS
from handle_drake.geometry.objects import ObjectSpec, dimensions
from handle_drake.grasp.planning import plan_grasp
from handle_drake.scenario import DumpScenario, Keyframe, object_spec, validate_scenario
from handle_drake.trial.plans import plan_scenario
from handle_drake.trial.simulate import ScenarioRunner

__all__ = [
    "Figure8Setup",
    "SETUPS",
    "ROTATIONS_DEG",
    "Figure8Result",
    "figure8_scenario",
    "run_figure8",
    "plot_figure8",
    "write_scenarios",
    "summary_table",
]

#: World rotations (about x, about y; degrees) the wrist turns the device to, in turn,
#: about the device's centre; the last returns it level.
ROTATIONS_DEG = ((25.0, 0.0), (-25.0, 0.0), (0.0, 25.0), (0.0, 0.0))
MOVE = 0.6  # s per rotation
HOLD = 0.8  # s still after each rotation
REST_SETTLE = 0.3  # s of each hold left out of the at-rest statistics
OPEN = 0.15  # s to open the hand
FALL = 0.6  # s simulated after the hand opened
RELEASE_PERIOD = 0.002  # s, sampling of the ideal sensor for the release instant


@dc.dataclass(frozen=True)
class Figure8Setup:
    """One experiment: the device, the grasp class and how the planner sees the device.

    plan_dims: (width x, depth y = grasp width, height z) of the box the planner
    grasps (m); R_PD: the device's orientation in that box's frame.
    """

    device: str
    grasp_class: str
    plan_dims: tuple[float, float, float]
    R_PD_rpy_deg: tuple[float, float, float] = (0.0, 0.0, 0.0)

    @property
    def name(self) -> str:
        return f"{self.device}_{self.grasp_class}"


SETUPS = {
    # The JoyWarrior (37 x 35 x 25 mm) on its side: a 25 mm tripod grasp across its
    # thickness (lying flat, 35 mm across, the open-loop plan does not hold it).
    "joywarrior": Figure8Setup("joywarrior", "tripod", (0.037, 0.025, 0.035), (90.0, 0.0, 0.0)),
    # The Wiimote lying flat: fingers along its 148 mm length, 36.2 mm across.
    "wiimote": Figure8Setup("wiimote", "parallel_extension", (0.148, 0.0362, 0.0308)),
}


def _setup(device) -> Figure8Setup:
    if isinstance(device, Figure8Setup):
        return device
    if device not in SETUPS:
        raise ValueError(f"device: expected one of {sorted(SETUPS)}, got {device!r}")
    return SETUPS[device]


def _unwrap(rpy, previous):
    """``rpy`` with each angle moved by multiples of 2 pi next to ``previous``."""
    return previous + angle_difference(rpy, previous)


def _rotated_wrist(plan, X_WB: RigidTransform, p_WC, R: RotationMatrix, previous):
    """Wrist command ``[x y z r p y]`` of the base pose turned by ``R`` (world) about
    the point ``p_WC``."""
    p = np.asarray(p_WC)
    X = RigidTransform(R, p - R @ p) @ X_WB
    rpy = _unwrap(RollPitchYaw(X.rotation()).vector(), np.asarray(previous[3:]))
    return [*map(float, X.translation()), *map(float, rpy)]


@dc.dataclass
class _Phases:
    rest: list  # (t0, t1) of the at-rest windows
    moving: list  # (t0, t1) of the wrist rotations
    held: tuple  # (t0, t1): lift done to the open command
    open_time: float
    rotations: list  # (about x, about y) deg per rest window


def figure8_scenario(device="joywarrior", rotations=ROTATIONS_DEG, seed: int = 0):
    """The planned scenario (with the device's accelerometer) and its phases."""

    setup = _setup(device)
    rotations = [tuple(float(a) for a in r) for r in rotations]
    if not rotations or any(len(r) != 2 or not all(map(math.isfinite, r)) for r in rotations):
        raise ValueError(f"rotations: expected (about_x, about_y) pairs in degrees, "
                         f"got {rotations!r}")
    width, depth, height = setup.plan_dims
    box = ObjectSpec("cuboid", width, dimensions={"depth": depth, "height": height})
    X_WP = RigidTransform([0.0, 0.0, height / 2])  # the planner's box on the table
    plan = plan_grasp(setup.grasp_class, box, X_WP)
    scenario = plan_scenario(plan)
    spec = ObjectSpec.default(setup.device)
    d = dimensions(spec)
    R_PD = RollPitchYaw(np.radians(setup.R_PD_rpy_deg)).ToRotationMatrix()
    extent = np.abs(R_PD.matrix()) @ np.array(list(d.values())[:3])
    if not np.allclose(extent, setup.plan_dims, atol=1e-9):
        raise ValueError(f"{setup.name}: the planner's box {setup.plan_dims} is not the "
                         f"device's extent {extent.round(4).tolist()}")
    scenario.object.kind = setup.device
    scenario.object.size = spec.size
    scenario.object.mass = None  # the catalogue's published mass
    scenario.object.X_WO = Transform(RigidTransform(R_PD, X_WP.translation()))
    scenario.object.accelerometer = AccelerometerConfig(seed=seed)
    scenario.random_seed = seed

    script = list(scenario.script)
    t = script[-1].time  # lift done
    lifted = plan.lifted()
    p_WC = X_WP.translation() + [0.0, 0.0, plan.lift_height]
    wrist = list(script[-1].wrist)
    phases = _Phases(rest=[], moving=[], held=(t, math.nan), open_time=math.nan, rotations=[])
    script.append(Keyframe(time=t + HOLD))  # hold level after the lift
    phases.rest.append((t + REST_SETTLE, t + HOLD))
    phases.rotations.append((0.0, 0.0))
    t += HOLD
    for about_x, about_y in rotations:
        R = (RotationMatrix.MakeXRotation(math.radians(about_x))
             @ RotationMatrix.MakeYRotation(math.radians(about_y)))
        wrist = _rotated_wrist(plan, lifted, p_WC, R, wrist)
        script.append(Keyframe(time=t + MOVE, wrist=wrist))
        script.append(Keyframe(time=t + MOVE + HOLD))
        phases.moving.append((t, t + MOVE))
        phases.rest.append((t + MOVE + REST_SETTLE, t + MOVE + HOLD))
        phases.rotations.append((about_x, about_y))
        t += MOVE + HOLD
    script.append(Keyframe(time=t + OPEN, hand=plan.command_dict(plan.preshape_command)))
    phases.open_time = t
    phases.held = (phases.held[0], t)
    scenario.script = script
    scenario.simulation_duration = t + OPEN + FALL
    validate_scenario(scenario)
    return scenario, phases, plan


#: The recorder samples this long after each device sample (s): Drake runs a publish
#: event at t before the discrete updates at t, so a sample at the device's own instant
#: would see the estimates of the sample before.
SAMPLE_DELAY = 2e-4


class _SensorTruth(LeafSystem):
    """``[true roll, true pitch, z]`` of the sensor frame S in world (rad, rad, m) from
    the object's pose: an output only (no state, no events)."""

    def __init__(self, X_OS: RigidTransform):
        super().__init__()
        self._X_OS = X_OS
        self._pose = self.DeclareAbstractInputPort("pose", AbstractValue.Make(RigidTransform()))
        self.DeclareVectorOutputPort("truth", 3, self._calc)

    def _calc(self, context, output):
        X_WS = self._pose.Eval(context) @ self._X_OS
        output.SetFromVector([*true_roll_pitch(X_WS.rotation()), float(X_WS.translation()[2])])


#: The recorded signals, in the order of :data:`_COLUMNS` after ``t``: (station
#: port, or None for the sensor truth, size).
_SIGNALS = ((None, 3), ("object.roll_pitch", 2), ("object.at_rest", 1),
            ("object.free_fall", 1), ("object.slip", 1), ("object.acceleration", 3))


@dc.dataclass
class _Recorder:
    """Drake's loggers on the instrument ports: the estimates, the flags and the true
    sensor pose, sampled ``SAMPLE_DELAY`` after each device sample by a
    ``ZeroOrderHold`` (period, offset) and logged by a ``VectorLogSink`` one period
    later; the ideal sensor (``object.acceleration_true``) logged every
    ``RELEASE_PERIOD`` s."""

    period: float
    hold: ZeroOrderHold
    samples: VectorLogSink
    ideal: VectorLogSink

    @classmethod
    def add(cls, builder, station, period: float, X_OS: RigidTransform) -> _Recorder:
        truth = builder.AddNamedSystem("sensor_truth", _SensorTruth(X_OS))
        builder.Connect(station.GetOutputPort("object.pose"), truth.get_input_port())
        mux = builder.AddNamedSystem("recorded_signals",
                                     Multiplexer([size for _, size in _SIGNALS]))
        for i, (port, _) in enumerate(_SIGNALS):
            source = truth.get_output_port() if port is None else station.GetOutputPort(port)
            builder.Connect(source, mux.get_input_port(i))
        hold = builder.AddNamedSystem("sample_after_device",
                                      ZeroOrderHold(period, mux.get_output_port().size(),
                                                    offset_sec=SAMPLE_DELAY))
        builder.Connect(mux.get_output_port(), hold.get_input_port())
        samples = LogVectorOutput(hold.get_output_port(), builder, period)
        samples.set_name("recorder")
        ideal = LogVectorOutput(station.GetOutputPort("object.acceleration_true"), builder,
                                RELEASE_PERIOD)
        ideal.set_name("ideal_recorder")
        return cls(period, hold, samples, ideal)

    def clear(self, root_context) -> None:
        for sink in (self.samples, self.ideal):
            sink.GetMutableLog(sink.GetMyMutableContextFromRoot(root_context)).Clear()

    def rows(self, root_context) -> np.ndarray:
        """(T, 12): ``t`` (the sampling instants, ``k period + SAMPLE_DELAY``) then the
        signals. The log at ``(k + 1) period`` holds the sample of ``k period +
        SAMPLE_DELAY``; the sample of the last period, not logged yet when the run
        ends, is read from the hold."""
        log = self.samples.GetLog(self.samples.GetMyContextFromRoot(root_context))
        k = np.round(log.sample_times() / self.period).astype(int) - 1
        keep = k >= 0  # the log at t = 0 holds the hold's initial zeros
        values = log.data()[:, keep].T
        k = k[keep]
        t_end = root_context.get_time()
        last = math.floor((t_end - SAMPLE_DELAY) / self.period + 1e-9)
        if last >= 0 and (not len(k) or last > k[-1]):
            held = self.hold.get_output_port().Eval(self.hold.GetMyContextFromRoot(root_context))
            values = np.vstack([values, held])
            k = np.append(k, last)
        t = SAMPLE_DELAY + k * self.period
        return np.column_stack([t, values])

    def ideal_norms(self, root_context) -> np.ndarray:
        """(T, 2): t, |f| of the ideal sensor."""
        log = self.ideal.GetLog(self.ideal.GetMyContextFromRoot(root_context))
        return np.column_stack([log.sample_times(), np.linalg.norm(log.data(), axis=0)])


_COLUMNS = ("t", "true_roll", "true_pitch", "sensor_z", "roll", "pitch", "at_rest",
            "free_fall", "slip", "ax", "ay", "az")


@dc.dataclass
class Figure8Result:
    """One run: the recorded samples (``data[column]``), the phases, the summary."""

    setup: Figure8Setup
    data: dict
    ideal: np.ndarray  # (T, 2): t, |f| of the ideal sensor
    phases: _Phases
    free_fall_threshold: float  # g
    wall_time: float
    sim_time: float

    def _mask(self, windows) -> np.ndarray:
        t = self.data["t"]
        mask = np.zeros(len(t), dtype=bool)
        for t0, t1 in windows:
            mask |= (t >= t0) & (t <= t1)
        return mask

    def errors_deg(self) -> np.ndarray:
        """(T, 2) roll and pitch error (estimate - true), degrees, wrapped."""
        est = np.column_stack([self.data["roll"], self.data["pitch"]])
        true = np.column_stack([self.data["true_roll"], self.data["true_pitch"]])
        return np.degrees(angle_difference(est, true))

    def release_time(self) -> float:
        """Start of the free fall the detector flagged: the first instant of the
        uninterrupted run of ideal-sensor readings below the free-fall threshold
        that contains the detection (a finger may still brush the object after
        the first dip). NaN when nothing was detected."""
        detected = self.detection_time()
        if not math.isfinite(detected):
            return math.nan
        t, norm = self.ideal[:, 0], self.ideal[:, 1]
        low = norm < self.free_fall_threshold * 9.80665
        i = int(np.searchsorted(t, detected, side="right")) - 1
        while i > 0 and low[i - 1] and t[i - 1] >= self.phases.open_time:
            i -= 1
        return float(t[i]) if low[i] else math.nan

    def detection_time(self) -> float:
        t, flag = self.data["t"], self.data["free_fall"]
        hit = (t >= self.phases.open_time) & (flag > 0.5)
        return float(t[hit][0]) if hit.any() else math.nan

    def summary(self) -> dict:
        err = self.errors_deg()
        rest, moving = self._mask(self.phases.rest), self._mask(self.phases.moving)
        held = self._mask([self.phases.held])

        def stats(mask):
            e = err[mask]
            if not len(e):
                return dict(rms=math.nan, max=math.nan)
            return dict(rms=float(np.sqrt(np.mean(e ** 2))), max=float(np.max(np.abs(e))))

        release, detected = self.release_time(), self.detection_time()
        z = self.data["sensor_z"]
        return {
            "device": self.setup.device,
            "grasp_class": self.setup.grasp_class,
            "rest_samples": int(rest.sum()),
            "rest_roll_pitch_deg": stats(rest),
            "moving_roll_pitch_deg": stats(moving),
            "at_rest_flag_at_rest": float(np.mean(self.data["at_rest"][rest] > 0.5)),
            "at_rest_flag_moving": float(np.mean(self.data["at_rest"][moving] > 0.5)),
            "held_through_rotations": bool(np.min(z[held]) > np.max(z[:5]) + 0.05),
            "false_free_fall_held": int(np.sum(self.data["free_fall"][held] > 0.5)),
            "false_slip_held": int(np.sum(self.data["slip"][held] > 0.5)),
            "release_time": release,
            "free_fall_detected": detected,
            "detection_delay_ms": (detected - release) * 1e3,
            "wall_time": self.wall_time,
            "sim_time": self.sim_time,
        }


def _runner_class():
    """A ScenarioRunner (the scenario's script on the trial harness) that also adds the
    experiment's recorder to the diagram it builds once."""

    class Figure8Runner(ScenarioRunner):
        def add_driver(self, builder, station):
            driver = super().add_driver(builder, station)
            profile = self.scenario.object.accelerometer.profile(self.scenario.object.kind)
            X_OS = instrument_X_OS(self.scenario, object_spec(self.scenario))
            self.recorder = _Recorder.add(builder, station, profile.period, X_OS)
            return driver

    return Figure8Runner


def run_figure8(device="joywarrior", rotations=ROTATIONS_DEG, seed: int = 0, meshcat=None,
                html=None) -> Figure8Result:
    """Plans, simulates and measures one Figure 8 experiment (see the module doc)."""
    scenario, phases, _ = figure8_scenario(device, rotations, seed)
    runner = _runner_class()(scenario, meshcat)
    runner.reset()
    runner.recorder.clear(runner.context)
    wall = runner.harness.advance(scenario.simulation_duration, html)
    rows = runner.recorder.rows(runner.context)
    data = {name: rows[:, i] for i, name in enumerate(_COLUMNS)}
    params = scenario.object.accelerometer.estimator_params(scenario.object.kind)
    return Figure8Result(_setup(device), data, runner.recorder.ideal_norms(runner.context),
                         phases, params.free_fall_threshold, wall, scenario.simulation_duration)


def summary_table(results) -> str:
    """The results as a text table (angles in degrees)."""
    head = (f"{'experiment':32s} {'rest RMS/max':>13s} {'moving RMS/max':>15s} "
            f"{'held':>5s} {'false FF/slip':>13s} {'FF delay':>9s}")
    lines = [head, "-" * len(head)]
    for r in results:
        s = r.summary()
        rest, moving = s["rest_roll_pitch_deg"], s["moving_roll_pitch_deg"]
        lines.append(
            f"{s['device'] + ' / ' + s['grasp_class']:32s} "
            f"{rest['rms']:6.2f}/{rest['max']:5.2f}  {moving['rms']:7.2f}/{moving['max']:6.2f}  "
            f"{'yes' if s['held_through_rotations'] else 'NO':>5s} "
            f"{s['false_free_fall_held']:6d}/{s['false_slip_held']:<6d} "
            f"{s['detection_delay_ms']:6.1f} ms")
    return "\n".join(lines)


def plot_figure8(results, path) -> Path:
    """Estimated and true roll and pitch over time, flags below; one column per run."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    results = list(results)
    fig, axes = plt.subplots(3, len(results), figsize=(6 * len(results), 7), sharex="col",
                             squeeze=False, gridspec_kw={"height_ratios": [2, 2, 1]})
    for column, r in enumerate(results):
        d = r.data
        for row, (name, label) in enumerate((("roll", "roll"), ("pitch", "pitch"))):
            ax = axes[row, column]
            # Unwrapped for display (a device on its side reads roll near +-180 deg).
            ax.plot(d["t"], np.degrees(np.unwrap(d[f"true_{name}"])), "k-", lw=2,
                    label="true (plant)")
            ax.plot(d["t"], np.degrees(np.unwrap(d[name])), "C1-", lw=1,
                    label="estimated (accelerometer)")
            for t0, t1 in r.phases.rest:
                ax.axvspan(t0, t1, color="C2", alpha=0.12, lw=0)
            ax.set_ylabel(f"{label} (deg)")
            ax.grid(alpha=0.3)
        axes[0, column].set_title(f"{r.setup.device}, {r.setup.grasp_class.replace('_', ' ')} "
                                  "grasp (green: at-rest phases)")
        axes[0, column].legend(loc="best", fontsize=8)
        ax = axes[2, column]
        ax.step(d["t"], d["at_rest"] * 0.9, where="post", label="at rest")
        ax.step(d["t"], d["free_fall"] * 1.0, where="post", label="free fall")
        ax.step(d["t"], d["slip"] * 0.8, where="post", label="slip")
        ax.axvline(r.phases.open_time, color="k", ls="--", lw=1)
        ax.set_xlabel("time (s)")
        ax.set_yticks([])
        ax.legend(loc="upper left", fontsize=8, ncol=3)
    fig.tight_layout()
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(path, dpi=110)
    plt.close(fig)
    return path


def write_scenarios(directory, seed: int = 0) -> list[Path]:
    """Writes ``instrumented_<device>_<class>.yaml`` for each setup; returns the paths."""

    out = []
    for key, setup in SETUPS.items():
        scenario, phases, plan = figure8_scenario(key, seed=seed)
        path = Path(directory) / f"instrumented_{setup.name}.yaml"
        header = (f"# Figure 8 (report section 3.4): {setup.device} in a "
                  f"{setup.grasp_class.replace('_', '-')} grasp, rotated by the wrist about "
                  f"{list(ROTATIONS_DEG)} deg (world x, y), then the hand opens at "
                  f"{phases.open_time:.2f} s.\n# Written by handle_drake.apps.figure8.experiments"
                  ".write_scenarios; the grasp planned by handle_drake.grasp.planning:\n"
                  f"# {plan.summary()}\n# Run: handle-drake simulate {path.name} "
                  "(measurements: handle-drake instruments)\n")
        path.write_text(header + DumpScenario(scenario))
        out.append(path)
    return out
