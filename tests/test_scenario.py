import math
from pathlib import Path

import numpy as np
import pytest
from pydrake.multibody.plant import MultibodyPlantConfig

from handle_drake.base.checks import ScenarioDeprecationWarning
from handle_drake.base.models import diagrams_dir
from handle_drake.scenario import (
    CanHandDriver,
    DumpScenario,
    FloatingWrist,
    LoadScenario,
    Scenario,
    ScenarioError,
    SimHandDriver,
    default_plant_config,
)

SCENARIO_FILES = sorted(diagrams_dir().glob("*.yaml"))


def test_defaults_are_a_valid_shadow_scenario():
    scenario = LoadScenario()
    assert scenario.hand.kind == "shadow"
    assert isinstance(scenario.driver, SimHandDriver)
    config = scenario.plant_config
    assert (config.contact_model, config.time_step) == ("point", 0.001)
    assert config.discrete_contact_approximation == "sap"
    assert config.use_sampled_output_ports is False


@pytest.mark.parametrize("path", SCENARIO_FILES, ids=[p.stem for p in SCENARIO_FILES])
def test_every_shipped_scenario_loads(path):
    assert isinstance(LoadScenario(filename=path), Scenario)


def test_override_applies_on_top_of_file(tmp_path):
    base = tmp_path / "base.yaml"
    base.write_text("object: {kind: cylinder, size: 0.05}\nplant_config: {time_step: 0.002}\n")
    scenario = LoadScenario(filename=base, data="object: {size: 0.07}\nrandom_seed: 3")
    assert scenario.object.kind == "cylinder"  # kept from the file
    assert scenario.object.size == 0.07  # replaced by the override
    assert scenario.plant_config.time_step == 0.002
    # A partial plant_config keeps the other fields (ours, then Drake's defaults).
    assert scenario.plant_config.discrete_contact_approximation == "sap"
    assert scenario.plant_config.use_sampled_output_ports is False
    assert scenario.plant_config.stiction_tolerance == MultibodyPlantConfig().stiction_tolerance
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
        ("plant_config: {contact_model: soft}", ["plant_config.contact_model", "soft"]),
        ("plant_config: {contact_model: hydroelastic}",
         ["plant_config.contact_model", "hydroelastic_with_fallback"]),
        ("plant_config: {discrete_contact_approximation: convex}",
         ["plant_config.discrete_contact_approximation", "convex"]),
        ("plant_config: {discrete_contact_approximation: tamsi}",
         ["plant_config.discrete_contact_approximation", "PD actuators"]),
        ("plant_config: {time_step: -0.001}", ["plant_config.time_step", "-0.001"]),
        ("plant_config: {time_step: 0}", ["plant_config.time_step"]),
        ("plant_config: {time_step: 0.5}", ["plant_config.time_step", "0.01"]),
        ("plant_config: {penetration_allowance: 0}", ["plant_config.penetration_allowance"]),
        ("plant_config: {penetration_allowance: .inf}", ["plant_config.penetration_allowance"]),
        ("plant_config: {stiction_tolerance: -1e-4}", ["plant_config.stiction_tolerance"]),
        ("plant_config: {stiction_tolerance: .nan}", ["plant_config.stiction_tolerance"]),
        ("plant_config: {sap_near_rigid_threshold: -1}", ["plant_config.sap_near_rigid_threshold"]),
        ("plant_config: {contact_surface_representation: quad}",
         ["plant_config.contact_surface_representation", "quad"]),
        ("plant_config: {use_sampled_output_ports: maybe}",
         ["plant_config.use_sampled_output_ports", "true or false"]),
        ("plant_config: {time_step: fast}", ["plant_config.time_step", "a number"]),
        ("plant_config: {timestep: 0.001}", ["plant_config.timestep", "unknown field"]),
        ("plant_config: 0.001", ["plant_config", "a mapping"]),
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


@pytest.mark.parametrize("old, new, field, value", [
    ("time_step: 0.002", "time_step", "time_step", 0.002),
    ("contact_approximation: lagged", "discrete_contact_approximation",
     "discrete_contact_approximation", "lagged"),
    ("contact_model: point", "contact_model", "contact_model", "point"),
    # The old "hydroelastic" was built as Drake's hydroelastic_with_fallback.
    ("contact_model: hydroelastic", "contact_model", "contact_model",
     "hydroelastic_with_fallback"),
])
def test_old_top_level_plant_keys_move_into_plant_config_with_a_warning(old, new, field, value):
    with pytest.warns(ScenarioDeprecationWarning) as record:
        scenario = LoadScenario(data=old)
    (warning,) = record
    message = str(warning.message)
    assert "\n" not in message and f"plant_config.{new}" in message and "override" in message
    assert getattr(scenario.plant_config, field) == value
    # Everything else is what the new key alone gives.
    key, text = old.split(": ")
    text = {"hydroelastic": "hydroelastic_with_fallback"}.get(text, text)
    assert repr(scenario) == repr(LoadScenario(data=f"plant_config: {{{new}: {text}}}"))


def test_old_keys_in_a_file_keep_the_file_and_override_order(tmp_path):
    path = tmp_path / "old.yaml"
    path.write_text("contact_model: hydroelastic\ntime_step: 0.002\ncontact_approximation: "
                    "similar\nplant_config: {stiction_tolerance: 0.001}\nobject: {size: 0.05}\n")
    with pytest.warns(ScenarioDeprecationWarning) as record:
        scenario = LoadScenario(filename=path, data="time_step: 0.0015")
    assert len(record) == 2  # one line for the file, one for the override
    assert "old.yaml" in str(record[0].message) and "override" in str(record[1].message)
    assert "contact_approximation -> plant_config.discrete_contact_approximation" in str(
        record[0].message)
    c = scenario.plant_config
    assert (c.contact_model, c.time_step, c.discrete_contact_approximation,
            c.stiction_tolerance) == ("hydroelastic_with_fallback", 0.0015, "similar", 0.001)
    assert scenario.object.size == 0.05
    # The dumped scenario is in the new form and loads back without a warning.
    text = DumpScenario(scenario)
    assert "\ntime_step" not in text and "\ncontact_approximation" not in text
    import warnings

    with warnings.catch_warnings():
        warnings.simplefilter("error")
        assert repr(LoadScenario(data=text)) == repr(scenario)


def test_old_key_and_its_new_field_together_are_refused():
    with pytest.raises(ScenarioError, match=r"time_step.*plant_config\.time_step"):
        LoadScenario(data="time_step: 0.002\nplant_config: {time_step: 0.001}")
    # A duplicated old key is still a duplicate (YAML would keep only the last one).
    with pytest.warns(ScenarioDeprecationWarning), pytest.raises(ScenarioError,
                                                                 match="duplicate"):
        LoadScenario(data="time_step: 0.001\ntime_step: 0.002")
    # Bad values under an old key name the new field.
    with pytest.warns(ScenarioDeprecationWarning), pytest.raises(
            ScenarioError, match="plant_config.discrete_contact_approximation.*PD actuators"):
        LoadScenario(data="contact_approximation: tamsi")


def test_python_callers_get_the_same_checks():
    from handle_drake.scenario import validate_scenario

    assert repr(Scenario().plant_config) == repr(default_plant_config())
    assert default_plant_config(time_step=0.002).discrete_contact_approximation == "sap"
    for config, field in ((default_plant_config(time_step=float("nan")), "time_step"),
                          (default_plant_config(contact_model="hydroelastic"), "contact_model"),
                          (MultibodyPlantConfig(discrete_contact_approximation=""),
                           "discrete_contact_approximation")):
        with pytest.raises(ScenarioError, match=f"plant_config.{field}"):
            validate_scenario(Scenario(plant_config=config))
    with pytest.raises(ScenarioError, match="plant_config: expected a pydrake"):
        validate_scenario(Scenario(plant_config={"time_step": 0.001}))
