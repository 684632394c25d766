"""An in-hand motion (Algorithm 1 frames) replays on the CAN hand as in simulation."""

import numpy as np
import pytest
from test_can_end_to_end import (  # noqa: F401 - processes is a fixture
    free_port,
    processes,
    random_bus,
    start_server,
    start_sim,
)

from handle_drake.apps.inhand.gist import frames
from handle_drake.apps.inhand.replay import replay_motion
from handle_drake.apps.inhand.task import InHandTrial
from handle_drake.base.hands import get_hand_spec
from handle_drake.scenario import LoadScenario


def test_gist_motion_replays_on_the_can_hand_and_in_simulation(processes):  # noqa: F811
    group, bus_port = random_bus()
    port = free_port()
    start_sim(processes, group, bus_port)
    start_server(processes, group, bus_port, port)
    trial = InHandTrial()
    gist, q0 = trial.gist, trial.initial_command()
    c = gist.initial_parameters()
    for m, sl in zip(gist.motions, gist.slices(), strict=True):  # flex strokes only
        c[sl][1:] = [0.8, 0.6] if (m.finger != "TH" and m.variation[0] > 0) else 0.0
    base = "hand: {kind: shadow, mount: !FixedMount {}}\nobject: null\ntable: null\n"
    last = frames(gist, c, q0, 50)[-1]
    names = get_hand_spec("shadow").joint_names
    actuated = get_hand_spec("shadow").actuated_joint_names
    runs = {}
    for hardware, driver in ((True, f"!CanHandDriver {{host: 127.0.0.1, port: {port}}}"),
                             (False, "!SimHandDriver {}")):
        scenario = LoadScenario(data=base + f"driver: {driver}\n")
        runs[hardware] = replay_motion(scenario, gist, c, q0, duration=1.0, hold=0.6,
                                       hardware=hardware)
    assert runs[True].wall_time >= 0.9 * 1.6  # real time on the CAN hand
    for joint in ("FFJ3", "MFJ3", "RFJ2"):
        for hardware, run in runs.items():
            np.testing.assert_allclose(run.commanded[-1, actuated.index(joint)],
                                       last[actuated.index(joint)], atol=1e-6)
            assert run.measured[-1, names.index(joint)] == pytest.approx(
                last[actuated.index(joint)], abs=0.03), (joint, hardware)
