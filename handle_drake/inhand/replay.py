"""Replays a parameter vector (Algorithm 1) on a hand station: simulated or the CAN hand.

The same :class:`GistMotionSource` that drives the trials drives ``hand.position``
of any station :func:`handle_drake.station.MakeHandStation` builds; with
``hardware=True`` (a ``!CanHandDriver`` scenario) the diagram runs in real
time against the CAN hand, exactly as ``handle-drake simulate --hardware``.
"""

from __future__ import annotations

import dataclasses as dc
import time

import numpy as np
from pydrake.systems.analysis import Simulator
from pydrake.systems.framework import DiagramBuilder
from pydrake.systems.primitives import VectorLogSink

from handle_drake.inhand.gist import ActionGist, GistMotionSource
from handle_drake.scenario import Scenario
from handle_drake.station import MakeHandStation

__all__ = ["replay_motion", "Replay"]


@dc.dataclass
class Replay:
    times: np.ndarray  # (T,) s
    commanded: np.ndarray  # (T, nu) rad, hand.position_commanded
    measured: np.ndarray  # (T, nq) rad, hand.position_measured
    wall_time: float


def replay_motion(scenario: Scenario, gist: ActionGist, c, q0, duration: float,
                  n_frames: int = 50, hold: float = 0.5, hardware: bool = False,
                  meshcat=None, log_period: float = 0.01) -> Replay:
    """Sends the frames of ``c`` to the scenario's hand for ``duration + hold`` seconds."""
    if scenario.hand.kind != "shadow":
        raise ValueError(f"hand.kind: the action gist drives the shadow hand, got "
                         f"{scenario.hand.kind!r}")
    builder = DiagramBuilder()
    station = builder.AddNamedSystem("station", MakeHandStation(scenario, meshcat,
                                                                hardware=hardware))
    source = builder.AddNamedSystem("motion", GistMotionSource(gist, q0, duration, n_frames,
                                                               parameters=c))
    builder.Connect(source.get_output_port(), station.GetInputPort("hand.position"))
    logs = {}
    for port in ("hand.position_commanded", "hand.position_measured"):
        output = station.GetOutputPort(port)
        logs[port] = builder.AddSystem(VectorLogSink(output.size(), log_period))
        builder.Connect(output, logs[port].get_input_port())
    diagram = builder.Build()
    simulator = Simulator(diagram)
    if hardware:
        simulator.set_target_realtime_rate(1.0)
    simulator.Initialize()
    start = time.perf_counter()
    simulator.AdvanceTo(duration + hold)
    wall = time.perf_counter() - start
    context = simulator.get_context()
    commanded = logs["hand.position_commanded"].FindLog(context)
    measured = logs["hand.position_measured"].FindLog(context)
    return Replay(commanded.sample_times().copy(), commanded.data().T.copy(),
                  measured.data().T.copy(), wall)
