"""Hostile but fair scenario files and command lines: refused before Drake, with the field.

Every case here once passed validation and then crashed inside Drake (a
``RuntimeError`` or a ``Failure at ...`` arriving as ``SystemExit``), hung, or
was silently misread. Each must now be a :class:`ScenarioError` (a
``ValueError``) whose message names the field and what was expected, and on
the command line a one-line error with exit code 2.
"""

import os
import socket
import stat

import pytest

from handle_drake.base.paths import check_output
from handle_drake.cli import main
from handle_drake.scenario import LoadScenario, ScenarioError

WRIST = "hand: {mount: !FloatingWrist {}}\n"

REFUSED = [
    # (override, words the message must hold)
    ("object: {size: 1e300}", ["object.size", "[0.001, 2]"]),
    ("object: {size: 1e-300}", ["object.size", "[0.001, 2]"]),
    ("object: {mass: 1e-30}", ["object.mass", "kg"]),
    ("object: {kind: cuboid, dimensions: {depth: 1e300}}", ["depth"]),
    ("plant_config: {time_step: 1e300}", ["plant_config.time_step", "[1e-05, 0.01]"]),
    ("plant_config: {time_step: 10}", ["plant_config.time_step"]),
    ("plant_config: {time_step: 1e-9}", ["plant_config.time_step"]),
    ("simulation_duration: 1e300", ["simulation_duration", "3600"]),
    ("plant_config: {time_step: 1e-5}\nsimulation_duration: 3000",
     ["2,000,000 steps", "plant_config.time_step"]),
    ("hand: {mount: !FloatingWrist {translation_kp: -5}}", ["hand.mount.translation_kp"]),
    ("hand: {mount: !FloatingWrist {rotation_kd: .nan}}", ["hand.mount.rotation_kd"]),
    ("hand: {mount: !FloatingWrist {rotation_kp: .inf}}", ["hand.mount.rotation_kp"]),
    ("hand: {mount: !FixedMount {X_WB: {rotation: !Uniform {}}}}",
     ["hand.mount.X_WB.rotation", "!Uniform"]),
    ("object: {X_WO: {translation: !UniformVector {min: [0, 0, 0], max: [1, 1, 1]}}}",
     ["object.X_WO.translation", "deterministic"]),
    ("hand: {mount: !FixedMount {X_WB: {rotation: !AngleAxis {angle_deg: 30, axis: [0, 0, 0]}}}}",
     ["rotation.axis", "non-zero"]),
    ("hand: {mount: !FixedMount {X_WB: {rotation: !AngleAxis {angle_deg: 30, "
     "axis: [1e-320, 0, 0]}}}}", ["rotation.axis"]),
    (WRIST + "script: [{time: 0.5, wrist: [1e6, 0, 0, 0, 0, 0]}]",
     ["script[0].wrist[0]", "workspace"]),
    # 1e4 rad of roll in 0.25 s made SAP's Hessian NaN (a RuntimeError from Drake)
    (WRIST + "script: [{time: 0, wrist: [0, 0, 0.3, 0, 0, 0]}, "
             "{time: 0.25, wrist: [0, 0, 0.3, 1e4, 0, 0]}]", ["script[1].wrist[3]", "rad"]),
    (WRIST + "script: [{time: 0, wrist: [0, 0, 0.3, 0, 0, 0]}, "
             "{time: 0.25, wrist: [0, 0, 9.9, 0, 0, 0]}]", ["speed", "m/s"]),
    ("plant_config: {time_step: 0.001, time_step: 0.002}", ["plant_config.time_step",
                                                            "duplicate"]),
    ("object: {size: 0.05, size: 0.07}", ["object.size", "duplicate"]),
    ("driver: 5", ["driver", "!SimHandDriver", "!CanHandDriver"]),
    ("!Foo {}", ["Scenario fields", "!Foo"]),
    ("object: {size: big}", ["object.size", "a number", "'big'"]),
    ("hand: [1, 2]", ["hand", "a mapping", "list"]),
    ("hand: {mount: !FixedMount {X_WB: {base_frame: gripper}}}", ["base_frame", "'world'"]),
    ("object: {colour: red}", ["object.colour", "unknown field"]),
    ("random_seed: -1", ["random_seed"]),
    ("object: {kind: " + "x" * 100000 + "}", ["object.kind", "100002 characters"]),
]


@pytest.mark.parametrize("text,words", REFUSED, ids=[c[0][:40] for c in REFUSED])
def test_out_of_range_and_misread_scenarios_are_refused_naming_the_field(text, words):
    with pytest.raises(ScenarioError) as info:
        LoadScenario(data=text)
    message = str(info.value)
    for word in words:
        assert word in message, message
    assert len(message) < 600


def test_plain_yaml_12_numbers_and_untagged_variants_still_load():
    scenario = LoadScenario(data="plant_config: {time_step: 1e-3}\nobject: {size: 5e-2}\n"
                                 "driver: {max_joint_velocity: 2}\n")
    assert scenario.plant_config.time_step == 1e-3 and scenario.object.size == 0.05
    assert scenario.driver.max_joint_velocity == 2.0


def test_a_directory_or_fifo_is_not_reported_as_missing(tmp_path):
    with pytest.raises(ValueError, match="expected a file, got the directory"):
        LoadScenario(filename=tmp_path)
    fifo = tmp_path / "fifo.yaml"
    os.mkfifo(fifo)
    with pytest.raises(ValueError, match="FIFO"):
        LoadScenario(filename=fifo)  # would block forever reading
    with pytest.raises(FileNotFoundError, match="nope.yaml"):
        LoadScenario(filename=tmp_path / "nope.yaml")


def test_output_paths_are_checked_before_any_work(tmp_path):
    with pytest.raises(ValueError, match="--html: expected a file path, got the directory"):
        check_output("--html", tmp_path)
    a_file = tmp_path / "f.txt"
    a_file.write_text("x")
    with pytest.raises(ValueError, match="--out: expected a directory, got the file"):
        check_output("--out", a_file, "dir")
    with pytest.raises(ValueError, match="but .* is a file"):
        check_output("--db", a_file / "sub" / "x.sqlite")
    with pytest.raises(ValueError, match="--html: .*(too long|at most)"):
        check_output("--html", tmp_path / ("a" * 300 + ".html"))
    assert check_output("--html", tmp_path / "new" / "x.html") == tmp_path / "new" / "x.html"
    assert not (tmp_path / "new").exists()  # checking creates nothing


@pytest.mark.skipif(os.geteuid() == 0, reason="root writes into read-only directories")
def test_read_only_output_place_is_refused(tmp_path):
    tmp_path.chmod(stat.S_IRUSR | stat.S_IXUSR)
    try:
        with pytest.raises(ValueError, match="read-only"):
            check_output("--html", tmp_path / "x.html")
    finally:
        tmp_path.chmod(stat.S_IRWXU)


def _cli(argv, capsys):
    code = main(argv)
    captured = capsys.readouterr()
    return code, captured.err


def test_cli_refuses_bad_scenarios_and_outputs_with_exit_2_and_no_traceback(tmp_path, capsys):
    scenario = tmp_path / "s.yaml"
    scenario.write_text("plant_config: {time_step: 10}\n")
    code, err = _cli(["simulate", str(scenario)], capsys)
    assert code == 2 and "plant_config.time_step" in err and "Traceback" not in err
    # An old top-level key: one warning line naming the new key, then the same error.
    scenario.write_text("time_step: 10\n")
    code, err = _cli(["simulate", str(scenario)], capsys)
    assert code == 2 and "Traceback" not in err
    assert "warning: " in err and "time_step -> plant_config.time_step" in err, err
    assert "error: plant_config.time_step" in err
    scenario.write_text("simulation_duration: 0.01\n")
    code, err = _cli(["simulate", str(scenario), "--html", str(tmp_path)], capsys)
    assert code == 2 and "--html" in err and "directory" in err
    code, err = _cli(["simulate", str(scenario), "--duration", "1e300"], capsys)
    assert code == 2 and "--duration" in err
    code, err = _cli(["simulate", str(tmp_path)], capsys)
    assert code == 2 and "directory" in err and "not found" not in err
    code, err = _cli(["simulate", str(scenario), "--hardware"], capsys)
    assert code == 2 and "!CanHandDriver" in err
    code, err = _cli(["report", "--out", str(scenario)], capsys)
    assert code == 2 and "--out: expected a directory" in err
    code, err = _cli(["babble", "--db", str(tmp_path)], capsys)
    assert code == 2 and "--db" in err


def test_hardware_without_a_server_is_refused_before_running(tmp_path, capsys):
    with socket.socket() as s:  # a free port: nothing listens there
        s.bind(("127.0.0.1", 0))
        port = s.getsockname()[1]
    scenario = tmp_path / "can.yaml"
    scenario.write_text(f"driver: !CanHandDriver {{port: {port}}}\nsimulation_duration: 0.01\n")
    code, err = _cli(["simulate", str(scenario), "--hardware"], capsys)
    assert code == 2 and f"127.0.0.1:{port}" in err and "can-server" in err


def test_can_server_listen_address_in_use_or_not_local(capsys):
    with socket.socket() as busy:
        busy.bind(("127.0.0.1", 0))
        busy.listen(1)
        port = busy.getsockname()[1]
        code, err = _cli(["can-server", "--listen", f"127.0.0.1:{port}", "--bus", "virtual"],
                         capsys)
    assert code == 2 and "in use" in err
    code, err = _cli(["can-server", "--listen", "192.0.2.1:0", "--bus", "virtual"], capsys)
    assert code == 2 and "192.0.2.1" in err and "Traceback" not in err
