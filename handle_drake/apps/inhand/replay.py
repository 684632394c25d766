"""Replays a parameter vector (Algorithm 1) on a hand station: simulated or the CAN hand.

The same :class:`GistMotionSource` that drives the trials drives ``hand.position``
of any station the :class:`~handle_drake.trial.harness.TrialHarness` builds; with
``hardware=True`` (a ``!CanHandDriver`` scenario) the diagram runs in real
time against the CAN hand, exactly as ``handle-drake simulate --hardware``.
"""

from __future__ import annotations

import dataclasses as dc

import numpy as np

from handle_drake.apps.inhand.gist import ActionGist, GistMotionSource
from handle_drake.scenario import Scenario
from handle_drake.trial.harness import TrialHarness

__all__ = ["replay_motion", "Replay"]


@dc.dataclass
class Replay:
    times: np.ndarray  # (T,) s
    commanded: np.ndarray  # (T, nu) rad, hand.position_commanded
    measured: np.ndarray  # (T, nq) rad, hand.position_measured
    wall_time: float


def replay_motion(scenario: Scenario, gist: ActionGist, c, q0, duration: float,
                  n_frames: int = 50, hold: float = 0.5, hardware: bool = False,
                  meshcat=None, html=None) -> Replay:
    """Sends the frames of ``c`` to the scenario's hand for ``duration + hold`` seconds."""
    if scenario.hand.kind != "shadow":
        raise ValueError(f"hand.kind: the action gist drives the shadow hand, got "
                         f"{scenario.hand.kind!r}")

    def add_motion(builder, station):
        source = builder.AddNamedSystem("motion", GistMotionSource(gist, q0, duration, n_frames,
                                                                   parameters=c))
        builder.Connect(source.get_output_port(), station.GetInputPort("hand.position"))
        return source

    harness = TrialHarness(scenario, add_motion, meshcat=meshcat, hardware=hardware,
                           log=("hand.position_commanded", "hand.position_measured"))
    harness.reset()
    harness.initialize()
    wall = harness.advance(duration + hold, html=html)
    logs = harness.logs()
    commanded, measured = logs["hand.position_commanded"], logs["hand.position_measured"]
    return Replay(commanded.sample_times().copy(), commanded.data().T.copy(),
                  measured.data().T.copy(), wall)
