"""A learned in-hand motion, replayed from its logged scenario, on the CAN hand (issue 45
item 7): ``handle-drake simulate <logged trial> --hardware`` with the scenario's driver
switched to ``!CanHandDriver``. The simulated firmware (``handle-drake can-sim``) and the
bus server (``can-server``) run as processes on a udp_multicast bus; the hand's reported
setpoints (``hand.position_commanded``: what the hand tracks, after the bus) are compared
with the learned frames computed from the trial's parameters by the gist itself."""

import numpy as np
import pytest
from test_can_end_to_end import free_port, processes, random_bus, start_server, start_sim

from handle_drake.apps.inhand.convergence import stroke_motion
from handle_drake.apps.inhand.screw_cap import CLEAR, ScrewCapTask, ScrewCapTrial
from handle_drake.base.hands import actuated_position_limits, get_hand_spec
from handle_drake.cli import main as cli_main
from handle_drake.scenario import LoadScenario
from handle_drake.trial.simulate import ScenarioRunner

__all__ = ["processes"]  # the fixture, imported


def test_the_logged_learned_motion_runs_on_the_can_hand(processes, tmp_path, capsys):
    trial = ScrewCapTrial(ScrewCapTask(**CLEAR, hold=0.1))
    x = stroke_motion(trial.gist)
    text = trial.scenario(x).logged()  # what the trial log stores for this trial
    path = tmp_path / "trial.yaml"
    path.write_text(text)
    group, bus_port = random_bus()
    port = free_port()
    start_sim(processes, group, bus_port)
    start_server(processes, group, bus_port, port)
    override = f"driver: !CanHandDriver {{port: {port}}}"
    scenario = LoadScenario(text=text, data=override)
    runner = ScenarioRunner(scenario, hardware=True,
                            log=("hand.position_commanded", "hand.position_measured",
                                 "hand.tactile"))
    result = runner.run()
    assert result.wall_time >= 0.9 * scenario.simulation_duration  # in real time
    log = runner.harness.logs()["hand.position_commanded"]
    times, setpoints = log.sample_times(), log.data().T
    # the truth: the gist's frames of the parameters, within the hand's joint limits
    lower, upper = actuated_position_limits(get_hand_spec("shadow"), 1.0)
    frames = np.clip(_frames(trial, x), lower, upper)
    moving = np.flatnonzero(np.ptp(frames, axis=0) > 0.05)
    assert moving.size >= 3  # the three fingers' J3 and J2
    during = times >= 0.45  # the motion starts at the settle's end (0.5 s)
    for j in moving:  # the hand was sent the learned motion: its extremes and its end
        assert setpoints[during, j].max() == pytest.approx(frames[:, j].max(), abs=2e-3)
        assert setpoints[during, j].min() == pytest.approx(frames[:, j].min(), abs=2e-3)
        assert setpoints[-1, j] == pytest.approx(frames[-1, j], abs=2e-3)
    # the command line does the same (one scenario file, the driver swapped)
    assert cli_main(["simulate", str(path), "--hardware", "--override", override]) == 0
    assert "simulated" in capsys.readouterr().out
    # and the learning command replays its best trial there (--hardware HOST:PORT)
    db = tmp_path / "run.sqlite"
    assert cli_main(["inhand", "--task", "screw_cap", "--optimizer", "random", "--trials", "1",
                     "--db", str(db), "--no-plot", "--no-html", "--no-progress",
                     "--hardware", f"127.0.0.1:{port}"]) == 0
    assert "replayed trial 0 on the CAN hand" in capsys.readouterr().out


def _frames(trial, x):
    from handle_drake.apps.inhand.screw_cap import GaitMotionSource

    scenario = trial.scenario(x)
    q0 = trial.initial_command()
    source = GaitMotionSource(scenario.action_gist(), q0, scenario.gait_duration,
                              scenario.n_frames, scenario.n_gaits)
    return source.frames_for(x)
