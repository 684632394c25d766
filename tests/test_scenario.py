import math
from pathlib import Path

import numpy as np
import pytest

from handle_drake.demo import diagrams_dir
from handle_drake.scenario import (
    CanHandDriver,
    DumpScenario,
    FloatingWrist,
    LoadScenario,
    Scenario,
    ScenarioError,
    SimHandDriver,
)

SCENARIO_FILES = sorted(diagrams_dir().glob("*.yaml"))


def test_defaults_are_a_valid_shadow_scenario():
    scenario = LoadScenario()
    assert scenario.hand.kind == "shadow"
    assert isinstance(scenario.driver, SimHandDriver)
    assert scenario.contact_model == "point"


@pytest.mark.parametrize("path", SCENARIO_FILES, ids=[p.stem for p in SCENARIO_FILES])
def test_every_shipped_scenario_loads(path):
    assert isinstance(LoadScenario(filename=path), Scenario)


def test_override_applies_on_top_of_file(tmp_path):
    base = tmp_path / "base.yaml"
    base.write_text("object: {kind: cylinder, size: 0.05}\ntime_step: 0.002\n")
    scenario = LoadScenario(filename=base, data="object: {size: 0.07}\nrandom_seed: 3")
    assert scenario.object.kind == "cylinder"  # kept from the file
    assert scenario.object.size == 0.07  # replaced by the override
    assert scenario.time_step == 0.002
    assert scenario.random_seed == 3


def test_tagged_variants_select_mount_and_driver():
    scenario = LoadScenario(data="""
hand: {kind: barrett, mount: !FloatingWrist {X_WB: {translation: [0, 0, 0.3]}}}
driver: !CanHandDriver {host: 127.0.0.1, port: 5000}
""")
    assert isinstance(scenario.hand.mount, FloatingWrist)
    assert isinstance(scenario.driver, CanHandDriver)
    assert scenario.driver.port == 5000


def test_dump_round_trips():
    scenario = LoadScenario(
        data="object: {kind: mug, size: 0.08}\nscript: [{time: 0.5, hand: {FFJ3: 1.0}}]")
    again = LoadScenario(data=DumpScenario(scenario))
    assert again.object.kind == "mug" and again.object.size == 0.08
    assert again.script[0].hand == {"FFJ3": 1.0}


@pytest.mark.parametrize(
    "text, words",
    [
        ("object: {kind: teapot}", ["object.kind", "teapot"]),
        ("object: {size: -0.05}", ["object.size", "-0.05"]),
        ("object: {size: 0}", ["object.size"]),
        ("object: {mass: .nan}", ["object.mass"]),
        ("hand: {kind: allegro}", ["hand.kind", "allegro"]),
        ("hand: {coupling_ratio: 0}", ["coupling_ratio"]),
        ("colour: red", ["colour"]),  # unknown field
        ("object: {kind: [sphere}", ["invalid scenario"]),  # malformed YAML
        ("object: {X_WO: {translation: [.nan, 0, 0]}}", ["object.X_WO", "finite"]),
        ("hand: {mount: !FixedMount {X_WB: {translation: [.inf, 0, 0]}}}", ["X_WB"]),
        ("contact_model: soft", ["contact_model", "soft"]),
        ("contact_approximation: convex", ["contact_approximation", "convex"]),
        ("contact_approximation: tamsi", ["contact_approximation", "PD actuators"]),
        ("time_step: -0.001", ["time_step"]),
        ("driver: !TeleportDriver {}", ["TeleportDriver"]),
        ("hand: {initial_position: {XXJ9: 1.0}}", ["XXJ9"]),
        ("object: {kind: cuboid, dimensions: {wingspan: 0.1}}", ["wingspan"]),
        ("object: {kind: cuboid, dimensions: {depth: -0.01}}", ["depth"]),
        ("script: [{time: 1.0}, {time: 0.5}]", ["script[1].time"]),
        ("script: [{time: 0.1, wrist: [0, 0, 0.2, 0, 0, 0]}]", ["FloatingWrist"]),
        ("hand: {mount: !FloatingWrist {}}\nscript: [{time: 0.1, wrist: [0, 0]}]",
         ["script[0].wrist", "6"]),
    ],
)
def test_bad_input_names_the_problem(text, words):
    with pytest.raises(ScenarioError) as error:
        LoadScenario(data=text)
    for word in words:
        assert word in str(error.value)


def test_missing_file_is_file_not_found(tmp_path):
    with pytest.raises(FileNotFoundError, match="nope.yaml"):
        LoadScenario(filename=tmp_path / "nope.yaml")


def test_empty_file_gives_defaults(tmp_path):
    path = Path(tmp_path / "empty.yaml")
    path.write_text("")
    assert LoadScenario(filename=path).object.kind == "sphere"


def test_rotation_in_degrees_is_converted():
    scenario = LoadScenario(data="object: {X_WO: {rotation: !Rpy {deg: [0, 0, 90]}}}")
    R = scenario.object.X_WO.GetDeterministicValue().rotation().matrix()
    np.testing.assert_allclose(R @ [1, 0, 0], [0, 1, 0], atol=1e-12)
    assert math.isclose(np.linalg.det(R), 1.0)
