"""The generated scenario files in diagrams/ are what their writers write today.

Each writer regenerates its files into a temporary ``diagrams`` folder (the command the
file's header names, run from a temporary directory) and the result is compared with the
committed file: the text between the numbers byte for byte (every key, every default, every
comment), the numbers to 1e-4 (m, rad, deg). The planned grasps come out of an IK solve whose
last digits differ from one machine to another (the committed files, written on another
machine by the same code, differ from this machine's solve by up to 2e-6 rad and 2e-5 deg),
which is all the tolerance allows.
"""

from __future__ import annotations

import re
from pathlib import Path

import numpy as np
import pytest

from handle_drake.cli import main as cli_main

ROOT = Path(__file__).resolve().parents[1]
NUMBER = re.compile(r"-?\d+\.\d+(?:[eE][-+]?\d+)?|-?\d+[eE][-+]?\d+")
TOLERANCE = 1e-4


def differences(written: str, committed: str) -> list[str]:
    """Where ``written`` differs from ``committed``: text between numbers, or a number > 1e-4."""
    problems = []
    written_lines, committed_lines = written.splitlines(), committed.splitlines()
    if len(written_lines) != len(committed_lines):
        problems.append(f"{len(written_lines)} lines written, {len(committed_lines)} committed")
    for number, (a, b) in enumerate(zip(written_lines, committed_lines, strict=False), 1):
        if NUMBER.split(a) != NUMBER.split(b):
            problems.append(f"line {number}: {a!r} != {b!r}")
            continue
        x = np.array([float(v) for v in NUMBER.findall(a)])
        y = np.array([float(v) for v in NUMBER.findall(b)])
        if x.size and np.max(np.abs(x - y)) > TOLERANCE:
            problems.append(f"line {number}: {a!r} != {b!r}")
    if written.endswith("\n") != committed.endswith("\n"):
        problems.append("final newline differs")
    return problems


def _check(folder: Path, names: list[str]) -> None:
    written = sorted(p.name for p in folder.glob("*.yaml"))
    assert written == sorted(names), written
    problems = {name: d for name in names
                if (d := differences((folder / name).read_text(),
                                     (ROOT / "diagrams" / name).read_text()))}
    assert not problems, f"regenerated files differ from the committed ones: {problems}"


def test_the_comparison_sees_a_key_a_comment_and_a_number():
    base = "# note\nwrist: [0.1, -0.2]\nvisualization:\n  publish_period: 0.03125\n"
    assert differences(base, base) == []
    assert differences(base.replace("0.1,", "0.100001,"), base) == []  # IK noise
    assert differences(base.replace("0.1,", "0.1002,"), base)  # a different plan
    assert differences(base + "  lcm_bus: default\n", base)  # a key more
    assert differences(base.replace("# note", "# other"), base)  # a comment
    assert differences(base.replace("0.03125", "0.03125\n"), base)


def test_midi_write_scenarios_reproduces_the_committed_files(tmp_path, monkeypatch, capsys):
    monkeypatch.chdir(tmp_path)
    assert cli_main(["midi", "write-scenarios", "diagrams"]) == 0
    _check(tmp_path / "diagrams", ["midi_jog_pinch.yaml", "midi_fader_push.yaml"])


@pytest.mark.slow
def test_instruments_write_scenarios_reproduces_the_committed_files(tmp_path, monkeypatch,
                                                                     capsys):
    monkeypatch.chdir(tmp_path)
    assert cli_main(["instruments", "--write-scenarios", "diagrams"]) == 0
    _check(tmp_path / "diagrams", ["instrumented_joywarrior_tripod.yaml",
                                   "instrumented_wiimote_parallel_extension.yaml"])


GRASP_SCENARIOS = sorted(p.name for p in (ROOT / "diagrams").glob("grasp_*.yaml"))


@pytest.mark.slow
def test_grasp_write_scenarios_reproduces_the_committed_files(tmp_path, monkeypatch):
    from handle_drake.apps.planning.cli import CLASS_OBJECTS
    from handle_drake.apps.planning.cli import main as planning_main

    monkeypatch.chdir(tmp_path)
    assert planning_main(["--write-scenarios", "diagrams"]) == 0
    assert GRASP_SCENARIOS == sorted(f"grasp_{name}.yaml" for name in CLASS_OBJECTS)
    _check(tmp_path / "diagrams", GRASP_SCENARIOS)


@pytest.mark.slow
@pytest.mark.parametrize("name", GRASP_SCENARIOS)
def test_every_shipped_grasp_scenario_lifts_its_object(name):
    """Read from the plant: the object ends >= 10 cm above where it started, and steady."""
    from handle_drake.scenario import LoadScenario
    from handle_drake.trial.simulate import ScenarioRunner, held_through_lift

    result = ScenarioRunner(LoadScenario(filename=str(ROOT / "diagrams" / name))).run()
    assert held_through_lift(result), result.object_position[::25, 2]
