"""The controller model and its encoder, the receiver, and the hand-control interface."""

import math

import mido
import numpy as np
import pytest
from pydrake.math import RigidTransform
from pydrake.multibody.plant import AddMultibodyPlant, MultibodyPlantConfig
from pydrake.systems.analysis import Simulator
from pydrake.systems.framework import DiagramBuilder

from handle_drake.apps.figure9.hand_control import BuildMidiHandControl
from handle_drake.base.hands import actuated_position_limits, get_hand_spec
from handle_drake.devices.midi.codec import REJECT_REASONS, fader_value
from handle_drake.devices.midi.device import AddMidiController, ControllerGeometry, control_layout
from handle_drake.devices.midi.mapping import LoadMidiMapping
from handle_drake.devices.midi.ports import MeshcatFaderPort, in_process_pair
from handle_drake.devices.midi.systems import (
    JOINT_MODE,
    SYNERGY_MODE,
    MidiControllerEncoder,
    MidiReceiver,
)
from handle_drake.scenario import LoadScenario

MAPPING = LoadMidiMapping()
SPEC = get_hand_spec("shadow")
NAMES = list(SPEC.actuated_joint_names)
FIXED_HAND = """
hand: {mount: !FixedMount {X_WB: {translation: [0, 0, 0.4]}}}
object: null
table: null
"""


def controller_diagram(fixed=True):
    builder = DiagramBuilder()
    plant, _ = AddMultibodyPlant(MultibodyPlantConfig(time_step=0.001), builder)
    instance = AddMidiController(plant, RigidTransform([0, 0, 0.0]), fixed=fixed)
    plant.Finalize()
    encoder = builder.AddSystem(MidiControllerEncoder(plant, instance, MAPPING, period=0.001))
    builder.Connect(plant.get_state_output_port(), encoder.get_plant_state_input_port())
    receiver = builder.AddSystem(MidiReceiver(MAPPING, period=0.001))
    builder.Connect(encoder.GetOutputPort("midi"), receiver.get_midi_input_port())
    simulator = Simulator(builder.Build())
    return simulator, plant, receiver


def test_model_has_every_control_as_a_joint_and_rests_still():
    simulator, plant, _ = controller_diagram()
    g = ControllerGeometry()
    for control in control_layout(g):
        joint = plant.GetJointByName(control.name)
        if control.kind == "fader":
            assert (joint.position_lower_limits()[0], joint.position_upper_limits()[0]) == (
                0.0, g.fader_travel)
        elif control.kind == "button":
            assert joint.position_upper_limits()[0] == g.button_travel
        else:
            assert math.isinf(joint.position_upper_limits()[0])  # endless
    simulator.AdvanceTo(0.3)
    q = plant.GetPositions(plant.GetMyContextFromRoot(simulator.get_context()))
    assert np.all(np.isfinite(q)) and np.abs(q).max() < 1e-4  # buttons held up by the preload


def test_free_base_falls_onto_nothing_but_stays_finite():
    simulator, plant, _ = controller_diagram(fixed=False)
    simulator.AdvanceTo(0.1)
    base = plant.GetBodyByName("base")
    z = base.EvalPoseInWorld(plant.GetMyContextFromRoot(simulator.get_context())).translation()[2]
    assert z == pytest.approx(-0.5 * 9.81 * 0.1**2, abs=2e-3)  # free fall, no table


def test_free_base_rests_flat_on_a_table():
    # Point contact, SAP, 2 ms (the experiments' settings). Box-on-box point
    # contact has a single contact point: without its corner feet the base
    # sank 12 mm into the table.
    from handle_drake.geometry.objects.plant import AddTable

    builder = DiagramBuilder()
    plant, _ = AddMultibodyPlant(MultibodyPlantConfig(
        time_step=0.002, contact_model="point", discrete_contact_approximation="sap"), builder)
    AddTable(plant, top_height=0.1)
    AddMidiController(plant, RigidTransform([0.05, 0.0, 0.1]), fixed=False)
    plant.Finalize()
    simulator = Simulator(builder.Build())
    simulator.AdvanceTo(0.5)
    context = plant.GetMyContextFromRoot(simulator.get_context())
    X = plant.GetBodyByName("base").EvalPoseInWorld(context)
    assert X.translation()[2] == pytest.approx(0.1, abs=3e-4)  # on the top, not in it
    assert np.abs(X.rotation().matrix() - np.eye(3)).max() < 1e-3  # flat
    assert np.abs(plant.GetBodyByName("base").EvalSpatialVelocityInWorld(context)
                  .translational()).max() < 1e-3  # at rest


@pytest.mark.parametrize("turns", [1.37, -2.61])
def test_known_wheel_rotation_gives_known_ticks_in_the_diagram(turns):
    simulator, plant, receiver = controller_diagram()
    context = simulator.get_mutable_context()
    plant_context = plant.GetMyMutableContextFromRoot(context)
    jog = plant.GetJointByName("jog")
    n = MAPPING.jog_ticks_per_turn
    for k, fraction in enumerate(np.linspace(0, 1, 60)):
        jog.set_angle(plant_context, 2 * math.pi * turns * fraction)
        jog.set_angular_rate(plant_context, 0.0)
        simulator.AdvanceTo(0.002 * (k + 1))
    angle = jog.get_angle(plant_context)
    values = receiver.control_values(receiver.GetMyContextFromRoot(context))
    assert values["jog"] == math.floor(angle * n / (2 * math.pi))
    assert abs(values["jog"] - turns * n) < 1.0


def test_the_encoder_keeps_its_levels_in_the_context_not_in_the_system():
    """A scan changes only the context's state: the system (shared by every context of the
    diagram) is the same after a simulation, and a fresh context starts from the rest."""
    simulator, plant, receiver = controller_diagram()
    diagram = simulator.get_system()
    encoder = next(s for s in diagram.GetSystems() if isinstance(s, MidiControllerEncoder))
    before = list(encoder._encoder.levels)
    context = simulator.get_mutable_context()
    plant_context = plant.GetMyMutableContextFromRoot(context)
    jog = plant.GetJointByName("jog")
    for k, fraction in enumerate(np.linspace(0, 1, 20)):
        jog.set_angle(plant_context, 2 * math.pi * fraction)
        jog.set_angular_rate(plant_context, 0.0)
        simulator.AdvanceTo(0.002 * (k + 1))
    assert receiver.control_values(receiver.GetMyContextFromRoot(context))["jog"] != 0
    assert list(encoder._encoder.levels) == before
    fresh = encoder.GetMyContextFromRoot(diagram.CreateDefaultContext())
    assert list(fresh.get_discrete_state(0).value()) == before


def test_fader_position_gives_its_midi_value():
    simulator, plant, receiver = controller_diagram()
    context = simulator.get_mutable_context()
    fader = plant.GetJointByName("fader4")
    fader.set_translation(plant.GetMyMutableContextFromRoot(context), 0.0213)
    simulator.AdvanceTo(0.01)
    values = receiver.control_values(receiver.GetMyContextFromRoot(context))
    assert values["fader4"] == fader_value(0.0213, 0.060) == 45
    assert values["fader3"] == -1  # never moved, never sent


def hand_control(**options):
    device, host = in_process_pair()
    feedback_host, feedback_device = in_process_pair()
    built = BuildMidiHandControl(LoadScenario(data=FIXED_HAND), port=host,
                                 feedback_port=feedback_host, **options)
    simulator = Simulator(built.diagram)
    return simulator, built, device, feedback_device


def cc(control, value, channel=0):
    return mido.Message("control_change", channel=channel, control=control, value=value)


def measured(built, simulator):
    q = built.station.GetOutputPort("hand.position_measured").Eval(
        built.station.GetMyContextFromRoot(simulator.get_context()))
    return {name: q[list(SPEC.joint_names).index(name)] for name in NAMES}


def test_fader_messages_move_the_hand_joints_to_their_targets_and_mode_switch_sends_feedback():
    """Joint mode: fader i sets joint DEFAULT_FADER_JOINTS[i] to lower + v/127 (upper - lower).

    Tolerance 0.03 rad after 1.2 s (the largest move, 1.57 rad at the 2 rad/s
    rate limit, takes 0.8 s; the PD loops settle in the rest)."""
    simulator, built, device, feedback = hand_control(max_joint_velocity=2.0)
    lower, upper = actuated_position_limits(SPEC, 1.0)
    values = [127, 64, 0, 100, 30, 90, 127, 10, 50]
    joints = ["FFJ3", "FFJ2", "MFJ3", "MFJ2", "RFJ3", "RFJ2", "LFJ3", "LFJ2", "THJ5"]
    for i, value in enumerate(values):
        device.send(cc(20 + i, value))
    simulator.AdvanceTo(1.2)
    q = measured(built, simulator)
    for joint, value in zip(joints, values, strict=True):
        j = NAMES.index(joint)
        target = lower[j] + value / 127 * (upper[j] - lower[j])
        assert q[joint] == pytest.approx(target, abs=0.03), joint
    control_context = built.control.GetMyContextFromRoot(simulator.get_context())
    assert built.control.get_mode(control_context) == JOINT_MODE

    # Mode button -> synergy mode: the faders are sent to the current posture's amplitudes.
    list(feedback.iter_pending())  # (what was sent at the start)
    device.send(mido.Message("note_on", note=84, velocity=127))
    device.send(mido.Message("note_off", note=84))
    simulator.AdvanceTo(1.25)
    assert built.control.get_mode(control_context) == SYNERGY_MODE
    sent = list(feedback.iter_pending())
    assert [m.control for m in sent] == list(range(20, 29))
    synergies = built.control._synergies
    lo, hi = synergies.amplitude_bounds()
    command = built.control.get_position_output_port().Eval(control_context)
    amplitudes = synergies.positions_to_amplitudes(command)
    for i, message in enumerate(sent[: len(lo)]):
        expected = np.clip((amplitudes[i] - lo[i]) / (hi[i] - lo[i]) * 127, 0, 127)
        assert abs(message.value - expected) <= 0.5 + 1e-9
    # Nothing jumped on the switch.
    simulator.AdvanceTo(1.5)
    assert max(abs(a - b) for a, b in zip(measured(built, simulator).values(), q.values(),
                                          strict=True)) < 0.02

    # Back to joint mode: the faders return to the values the user left them at.
    device.send(mido.Message("note_on", note=84, velocity=127))
    simulator.AdvanceTo(1.55)
    back = list(feedback.iter_pending())
    assert [m.value for m in back] == pytest.approx(values, abs=1)


def test_faders_are_sent_to_the_initial_command_at_start():
    # Shadow limits (reference hand_kinematics.md): FFJ3 -0.2618..1.5708 rad,
    # THJ5 +-1.0472 rad; the other fader joints start at 0 (FFJ2 etc. 0..1.5708).
    initial = np.zeros(len(NAMES))
    initial[NAMES.index("FFJ3")], initial[NAMES.index("THJ5")] = 1.0, -0.5
    simulator, built, device, feedback = hand_control(initial_command=initial, synergies=None)
    simulator.Initialize()
    sent = list(feedback.iter_pending())
    assert [m.control for m in sent] == list(range(20, 29))  # fader1..9, nothing else
    expected = [round((1.0 + 0.2618) / (1.5708 + 0.2618) * 127), 0,  # FFJ3 87, FFJ2
                round(0.2618 / 1.8326 * 127), 0, round(0.2618 / 1.8326 * 127), 0,  # MF, RF
                round(0.2618 / 1.8326 * 127), 0,  # LF
                round((-0.5 + 1.0472) / 2.0944 * 127)]  # THJ5 33
    assert [m.value for m in sent] == expected
    # Touching a fader one count from there moves its joint by one count's worth.
    device.send(cc(20, expected[0] + 1))
    simulator.AdvanceTo(0.05)
    command = built.control.get_position_output_port().Eval(
        built.control.GetMyContextFromRoot(simulator.get_context()))
    assert command[NAMES.index("FFJ3")] == pytest.approx(
        -0.2618 + (expected[0] + 1) / 127 * 1.8326, abs=1e-3)


def test_synergy_mode_faders_set_synergy_amplitudes():
    """Synergy mode: fader i sets amplitude i to lo_i + v/127 (hi_i - lo_i); the target is
    mean + a @ components[:k] within the joint limits (the PCA basis, written out here)."""
    simulator, built, device, feedback = hand_control(max_joint_velocity=4.0)
    simulator.Initialize()
    list(feedback.iter_pending())
    device.send(mido.Message("note_on", note=84, velocity=127))  # -> synergy mode
    simulator.AdvanceTo(0.02)
    faders = [m.value for m in feedback.iter_pending()]
    synergies = built.control._synergies
    lo, hi = synergies.amplitude_bounds()
    k = len(lo)
    assert 1 <= k <= 9 and len(faders) == 9
    device.send(cc(20, 127))  # fader1: the first synergy at the top of its range
    simulator.AdvanceTo(1.5)
    a = np.array([lo[i] + (127 if i == 0 else faders[i]) / 127 * (hi[i] - lo[i])
                  for i in range(k)])
    lower, upper = actuated_position_limits(SPEC, 1.0)
    expected = np.clip(synergies.mean + a @ synergies.components[:k], lower, upper)
    control_context = built.control.GetMyContextFromRoot(simulator.get_context())
    assert built.control.get_mode(control_context) == SYNERGY_MODE
    command = built.control.get_position_output_port().Eval(control_context)
    assert command == pytest.approx(expected, abs=1e-9)
    q = measured(built, simulator)
    for joint in ("FFJ3", "MFJ3", "THJ5", "THJ4"):
        assert q[joint] == pytest.approx(expected[NAMES.index(joint)], abs=0.03), joint


def test_knob_ticks_move_a_joint_relatively_and_the_command_is_rate_limited():
    simulator, built, device, _ = hand_control(max_joint_velocity=1.0, period=0.005,
                                               radians_per_tick=0.01)
    logger_port = built.control.get_position_output_port()
    context = simulator.get_mutable_context()
    device.send(cc(20, 127))  # FFJ3 to its upper limit: 1.57 rad
    device.send(cc(30, 0x05))  # knob1 (FFJ4) +5 ticks, signed-bit
    device.send(cc(30, 0x45))  # knob1 -5 ticks
    device.send(cc(30, 0x0A))  # +10 ticks
    previous = logger_port.Eval(built.control.GetMyContextFromRoot(context)).copy()
    steps = []
    for k in range(1, 60):
        simulator.AdvanceTo(0.005 * k)
        now = logger_port.Eval(built.control.GetMyContextFromRoot(context)).copy()
        steps.append(np.abs(now - previous).max())
        previous = now
    assert max(steps) <= 1.0 * 0.005 + 1e-12
    assert previous[NAMES.index("FFJ4")] == pytest.approx(0.10, abs=1e-9)


def test_bad_messages_are_counted_and_the_hand_still_answers():
    simulator, built, device, _ = hand_control()
    budget = 256
    bad = [mido.Message("sysex", data=[1, 2, 3]), cc(20, 5, channel=9), cc(99, 5),
           mido.Message("pitchwheel", pitch=1000), cc(60, 0)]
    for message in bad:
        device.send(message)
    simulator.AdvanceTo(0.01)
    for _ in range(budget + 100):  # a burst within one update
        device.send(cc(21, 64))
    simulator.AdvanceTo(0.02)
    device.send(cc(20, 127))
    simulator.AdvanceTo(1.0)
    counts = built.control.midi_counts(built.control.GetMyContextFromRoot(simulator.get_context()))
    assert counts["sysex"] == counts["unknown_channel"] == counts["unknown_control"] == 1
    assert counts["unexpected_type"] == counts["out_of_range"] == 1
    assert counts["burst"] == 100 and counts["rejected"] == 105
    assert counts["accepted"] == budget + 1
    assert set(counts) == {"accepted", "rejected", *REJECT_REASONS}
    assert measured(built, simulator)["FFJ3"] == pytest.approx(math.pi / 2, abs=0.03)


def test_meshcat_sliders_drive_the_hand():
    from pydrake.geometry import Meshcat

    meshcat = Meshcat()
    port = MeshcatFaderPort(meshcat, MAPPING)
    built = BuildMidiHandControl(LoadScenario(data=FIXED_HAND), port=port, feedback_port=port,
                                 synergies=None)
    simulator = Simulator(built.diagram)
    simulator.Initialize()  # the sliders are sent to the initial command
    assert meshcat.GetSliderValue("MIDI fader1") == round(0.2618 / 1.8326 * 127)  # FFJ3 = 0
    meshcat.SetSliderValue("MIDI fader1", 127)  # as if dragged in the browser
    simulator.AdvanceTo(1.0)
    assert measured(built, simulator)["FFJ3"] == pytest.approx(math.pi / 2, abs=0.03)
    port.close()


def test_bad_arguments_name_the_field():
    from handle_drake.devices.midi.systems import MidiHandControl

    with pytest.raises(ValueError, match="fader_joints"):
        MidiHandControl("shadow", MAPPING, fader_joints=["XXJ9"])
    with pytest.raises(ValueError, match="synergy mode needs synergies"):
        MidiHandControl("shadow", MAPPING, mode=SYNERGY_MODE)
    with pytest.raises(ValueError, match="max_joint_velocity"):
        MidiHandControl("shadow", MAPPING, max_joint_velocity=-1.0)
    with pytest.raises(TypeError, match="port"):
        MidiHandControl("shadow", MAPPING, port=object())
    barrett = MidiHandControl("barrett", MAPPING)  # faders 1-4: spread and the three fingers
    assert barrett.get_position_output_port().size() == 4
    assert barrett._fader_joint == [0, 1, 2, 3, -1, -1, -1, -1, -1]


def test_station_exports_the_controller_ports_and_checks_its_config(tmp_path):
    from handle_drake.scenario import ScenarioError
    from handle_drake.station import GetPlant, MakeHandStation

    scenario = LoadScenario(data="object: null\ntable: {top_height: 0.02}\n"
                                 "midi_controller: {X_WC: {translation: [0.1, 0, 0.5]}}")
    station = MakeHandStation(scenario)
    outputs = {station.get_output_port(i).get_name(): station.get_output_port(i)
               for i in range(station.num_output_ports())}
    assert outputs["midi_controller.control_positions"].size() == len(MAPPING.controls)
    assert "midi_controller.midi" in outputs
    plant = GetPlant(station)
    X_WC = plant.GetBodyByName("base").EvalPoseInWorld(plant.CreateDefaultContext())
    assert X_WC.translation() == pytest.approx([0.1, 0.0, 0.02])  # on the table top
    for override, field in (("midi_controller: {scan_period: 0}", "scan_period"),
                            (f"midi_controller: {{mapping: {tmp_path / 'x.yaml'}}}", "mapping")):
        with pytest.raises(ScenarioError, match=f"midi_controller.{field}"):
            LoadScenario(data=override)
