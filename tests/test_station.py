import numpy as np
import pytest
from pydrake.systems.analysis import Simulator
from pydrake.systems.framework import DiagramBuilder
from pydrake.systems.primitives import ConstantVectorSource

from handle_drake.base.hands import get_hand_spec
from handle_drake.base.models import diagrams_dir
from handle_drake.geometry.objects import KINDS
from handle_drake.scenario import LoadScenario
from handle_drake.station import GetPlant, MakeHandStation, object_body
from handle_drake.trial.simulate import ScenarioRunner

SCENARIO_FILES = sorted(diagrams_dir().glob("*.yaml"))

DOCUMENTED_OUTPUTS = {
    "hand.position_commanded", "hand.position_measured", "hand.velocity_estimated",
    "hand.state_estimated", "hand.tactile", "object.pose", "object.spatial_velocity",
    "object.position", "contact_results", "query_object", "body_poses", "plant_state",
}


def _simulate_random(scenario, duration=0.1, seed=0):
    """Station under a random (in-limits) hand command; returns final plant state."""
    station = MakeHandStation(scenario)
    spec = get_hand_spec(scenario.hand.kind)
    rng = np.random.default_rng(seed)
    lower, upper = spec.joint_lower_limits, spec.joint_upper_limits
    index = [spec.joint_names.index(n) for n in spec.actuated_joint_names]
    command = rng.uniform(lower[index], upper[index])
    builder = DiagramBuilder()
    builder.AddSystem(station)
    source = builder.AddSystem(ConstantVectorSource(command))
    builder.Connect(source.get_output_port(), station.GetInputPort("hand.position"))
    diagram = builder.Build()
    simulator = Simulator(diagram)
    simulator.AdvanceTo(duration)
    context = station.GetMyContextFromRoot(simulator.get_context())
    return station, context, station.GetOutputPort("plant_state").Eval(context)


@pytest.mark.parametrize("path", SCENARIO_FILES, ids=[p.stem for p in SCENARIO_FILES])
def test_every_scenario_simulates_and_stays_finite(path):
    # Hardware scenarios run the same diagram in simulation with the sim driver.
    _, _, state = _simulate_random(LoadScenario(filename=path,
                                                data="driver: !SimHandDriver {}"))
    assert np.all(np.isfinite(state))


@pytest.mark.parametrize("hand", ["shadow", "barrett"])
@pytest.mark.parametrize("contact_model", ["point", "hydroelastic_with_fallback"])
@pytest.mark.parametrize("mount", ["!FixedMount {X_WB: {translation: [0, 0, 0.4]}}",
                                   "!FloatingWrist {X_WB: {translation: [0, 0, 0.4]}}"])
def test_hands_mounts_and_contact_models_simulate(hand, contact_model, mount):
    scenario = LoadScenario(data=f"hand: {{kind: {hand}, mount: {mount}}}\n"
                                 f"plant_config: {{contact_model: {contact_model}}}")
    _, _, state = _simulate_random(scenario)
    assert np.all(np.isfinite(state))


@pytest.mark.parametrize("kind", KINDS)
def test_every_object_kind_rests_in_the_station(kind):
    scenario = LoadScenario(data=f"object: {{kind: {kind}, size: 0.06}}\n"
                                 "hand: {mount: !FixedMount {X_WB: {translation: [0, 0, 0.5]}}}")
    station, context, state = _simulate_random(scenario, duration=0.2)
    assert np.all(np.isfinite(state))
    # Nothing touches the object but the table: it stays where it was put.
    p_WO = station.GetOutputPort("object.position").Eval(context)
    plant = GetPlant(station)
    X_WO = station.GetOutputPort("object.pose").Eval(context)
    np.testing.assert_allclose(X_WO.translation(), p_WO)
    expected = plant.GetDefaultFloatingBaseBodyPose(object_body(plant)).translation()
    np.testing.assert_allclose(p_WO, expected, atol=3e-3)


@pytest.mark.parametrize("hand, nq, nu, tips", [("shadow", 24, 20, 5), ("barrett", 8, 4, 3)])
def test_ports_have_documented_names_and_sizes(hand, nq, nu, tips):
    station = MakeHandStation(LoadScenario(
        data=f"hand: {{kind: {hand}, mount: !FloatingWrist {{}}}}"))
    outputs = {station.get_output_port(i).get_name(): station.get_output_port(i)
               for i in range(station.num_output_ports())}
    inputs = {station.get_input_port(i).get_name(): station.get_input_port(i)
              for i in range(station.num_input_ports())}
    assert DOCUMENTED_OUTPUTS | {"wrist.pose_measured"} == set(outputs)
    # applied_spatial_force: the plant's external forces (optional, simulation only)
    assert {"hand.position", "wrist.pose", "applied_spatial_force"} == set(inputs)
    assert inputs["hand.position"].size() == nu
    assert inputs["wrist.pose"].size() == 6
    assert outputs["hand.position_commanded"].size() == nu
    assert outputs["hand.position_measured"].size() == nq
    assert outputs["hand.velocity_estimated"].size() == nq
    assert outputs["hand.state_estimated"].size() == 2 * nq
    assert outputs["hand.tactile"].size() == tips


def test_fixed_mount_without_object_has_no_wrist_or_object_ports():
    station = MakeHandStation(LoadScenario(data="object: null\ntable: null"))
    names = {station.get_output_port(i).get_name() for i in range(station.num_output_ports())}
    assert "wrist.pose_measured" not in names and "object.pose" not in names


@pytest.mark.parametrize("ratio", [1.0, 1.1])
def test_coupler_holds_in_the_station(ratio):
    scenario = LoadScenario(data=f"""
object: null
table: null
hand: {{coupling_ratio: {ratio}, mount: !FixedMount {{X_WB: {{translation: [0, 0, 0.5]}}}}}}
script: [{{time: 0.0}}, {{time: 0.3, hand: {{FFJ2: 1.0, MFJ2: 0.6, RFJ2: 0.8, LFJ2: 0.4}}}}]
simulation_duration: 0.8
""")
    result = ScenarioRunner(scenario).run()
    names = get_hand_spec("shadow").joint_names
    q = result.hand_position[-1]
    for finger, target in (("FF", 1.0), ("MF", 0.6), ("RF", 0.8), ("LF", 0.4)):
        j2, j1 = q[names.index(f"{finger}J2")], q[names.index(f"{finger}J1")]
        assert j2 == pytest.approx(target, abs=0.03)
        assert j1 == pytest.approx(ratio * j2, abs=1e-3)


def test_command_is_rate_limited_and_clamped():
    scenario = LoadScenario(data="""
object: null
table: null
hand: {mount: !FixedMount {X_WB: {translation: [0, 0, 0.5]}}}
driver: !SimHandDriver {max_joint_velocity: 2.0}
script: [{time: 0.0, hand: {FFJ3: 5.0}}]
simulation_duration: 0.3
""")
    runner = ScenarioRunner(scenario)
    runner.run(0.3)
    station_context = runner.station.GetMyContextFromRoot(runner.context)
    spec = get_hand_spec("shadow")
    commanded = runner.station.GetOutputPort("hand.position_commanded").Eval(station_context)
    # 5 rad is beyond the 1.5708 upper limit; at 2 rad/s the command needs
    # 0.785 s to get there, so after 0.3 s it has moved 0.6 rad.
    assert commanded[spec.actuated_joint_names.index("FFJ3")] == pytest.approx(0.6, abs=0.01)
    runner.run(1.0)
    commanded = runner.station.GetOutputPort("hand.position_commanded").Eval(station_context)
    assert commanded[spec.actuated_joint_names.index("FFJ3")] == pytest.approx(np.pi / 2)


def test_floating_wrist_tracks_pose_command():
    target = [0.1, -0.05, 0.35, 0.3, -0.2, 0.5]
    scenario = LoadScenario(data=f"""
object: null
hand: {{mount: !FloatingWrist {{X_WB: {{translation: [0, 0, 0.3]}}}}}}
script: [{{time: 0.0}}, {{time: 0.3, wrist: {target}}}]
""")
    runner = ScenarioRunner(scenario)
    runner.run(0.8)
    context = runner.station.GetMyContextFromRoot(runner.context)
    measured = runner.station.GetOutputPort("wrist.pose_measured").Eval(context)
    np.testing.assert_allclose(measured, target, atol=2e-3)
    # The hand base really is there: compare with the plant's body pose.
    plant = GetPlant(runner.station)
    X_WB = plant.GetBodyByName("forearm").EvalPoseInWorld(
        plant.GetMyContextFromRoot(runner.context))
    from pydrake.math import RollPitchYaw

    np.testing.assert_allclose(X_WB.translation(), target[:3], atol=2e-3)
    np.testing.assert_allclose(RollPitchYaw(X_WB.rotation()).vector(), target[3:], atol=2e-3)


@pytest.mark.parametrize("approximation", ["sap", "similar", "lagged"])
def test_station_uses_the_scenario_contact_approximation(approximation):
    """The field reaches the plant, and every SAP-family approximation drives
    the PD actuators (under TAMSI the joints would silently never move)."""
    scenario = LoadScenario(data=f"plant_config: {{discrete_contact_approximation: "
                                 f"{approximation}}}\nobject: null\n"
                                 "table: null\nscript: [{time: 0.3, hand: {FFJ3: 1.0}}]")
    runner = ScenarioRunner(scenario)
    plant = GetPlant(runner.station)
    assert plant.get_discrete_contact_approximation().name == "k" + approximation.capitalize()
    result = runner.run(0.5)
    spec = get_hand_spec("shadow")
    ffj3 = spec.joint_names.index("FFJ3")
    assert result.hand_position[-1, ffj3] == pytest.approx(1.0, abs=0.05)


def test_tactile_is_zero_in_free_air():
    free = LoadScenario(data="object: null\ntable: null\nsimulation_duration: 0.2")
    assert np.all(ScenarioRunner(free).run().tactile[-1] == 0.0)


@pytest.mark.parametrize("contact_model", ["point", "hydroelastic_with_fallback"])
def test_tactile_reads_the_weight_of_a_body_at_rest(contact_model):
    """A 0.2 kg "fingertip" resting on a table presses with m g = 1.962 N."""
    from pydrake.geometry import (
        AddCompliantHydroelasticProperties,
        Box,
        ProximityProperties,
        Sphere,
    )
    from pydrake.math import RigidTransform
    from pydrake.multibody.plant import AddMultibodyPlant, CoulombFriction, MultibodyPlantConfig
    from pydrake.multibody.tree import SpatialInertia, UnitInertia

    from handle_drake.systems.tactile import FingertipTactile

    builder = DiagramBuilder()
    plant, _ = AddMultibodyPlant(MultibodyPlantConfig(
        time_step=0.001, discrete_contact_approximation="sap", contact_model=contact_model),
        builder)
    mass, radius = 0.2, 0.01
    tip = plant.AddRigidBody("tip", SpatialInertia(mass, np.zeros(3),
                                                   UnitInertia.SolidSphere(radius)))
    props = ProximityProperties()
    AddCompliantHydroelasticProperties(0.01, 1e6, props)
    props.AddProperty("material", "coulomb_friction", CoulombFriction(0.5, 0.5))
    plant.RegisterCollisionGeometry(tip, RigidTransform(), Sphere(radius), "tip", props)
    plant.RegisterCollisionGeometry(plant.world_body(), RigidTransform([0, 0, -0.05]),
                                    Box(1, 1, 0.1), "table", props)
    plant.Finalize()
    tactile = builder.AddSystem(FingertipTactile(plant, [tip]))
    builder.Connect(plant.get_contact_results_output_port(),
                    tactile.get_contact_results_input_port())
    diagram = builder.Build()
    simulator = Simulator(diagram)
    plant.SetFreeBodyPose(plant.GetMyMutableContextFromRoot(simulator.get_mutable_context()),
                          tip, RigidTransform([0, 0, radius]))
    simulator.AdvanceTo(0.5)
    force = tactile.get_output_port().Eval(tactile.GetMyContextFromRoot(simulator.get_context()))
    assert force[0] == pytest.approx(mass * 9.81, rel=0.02)


def test_reset_replays_the_same_trial_without_rebuilding():
    runner = ScenarioRunner(LoadScenario(filename=diagrams_dir() / "shadow_sphere_grasp.yaml"))
    first = runner.run(0.6)
    second = runner.run(0.6)
    np.testing.assert_array_equal(first.object_position, second.object_position)
    np.testing.assert_array_equal(first.hand_position, second.hand_position)


def test_hardware_flag_needs_a_can_driver():
    with pytest.raises(ValueError, match="CanHandDriver"):
        MakeHandStation(LoadScenario(), hardware=True)
    with pytest.raises(ValueError, match="SimHandDriver"):
        MakeHandStation(LoadScenario(data="driver: !CanHandDriver {port: 1}"))


@pytest.mark.parametrize("text, time_step, model, approximation, surface", [
    ("", 0.001, "kPoint", "kSap", "kPolygon"),  # the defaults
    ("{time_step: 0.002, contact_model: hydroelastic_with_fallback, "
     "discrete_contact_approximation: similar, contact_surface_representation: triangle}",
     0.002, "kHydroelasticWithFallback", "kSimilar", "kTriangle"),
    ("{time_step: 0.0005, discrete_contact_approximation: lagged}", 0.0005, "kPoint", "kLagged",
     "kPolygon"),
])
def test_the_plant_is_built_from_the_scenario_plant_config(text, time_step, model, approximation,
                                                           surface):
    """Read back from the station's MultibodyPlant: what plant_config says, and the object
    (and only with a hydroelastic model) gets hydroelastic properties."""
    from pydrake.geometry import Role

    scenario = LoadScenario(data=f"plant_config: {text}" if text else "")
    station = MakeHandStation(scenario)
    plant = GetPlant(station)
    assert plant.time_step() == time_step
    assert plant.get_contact_model().name == model
    assert plant.get_discrete_contact_approximation().name == approximation
    assert plant.get_contact_surface_representation().name == surface
    scene_graph = station.GetSubsystemByName("scene_graph")
    inspector = scene_graph.model_inspector()
    geometry = plant.GetCollisionGeometriesForBody(object_body(plant))[0]
    props = inspector.GetProperties(geometry, Role.kProximity)
    assert props.HasGroup("hydroelastic") == (model != "kPoint")
