"""The simulated hand driver and the floating-wrist driver.

Both sit between the station's exported command ports and the plant's
PD-controlled actuators (MultibodyPlant's ``desired_state`` input, SAP solver),
and translate the plant's full state into the hand's measured signals in the
joint order of :class:`handle_drake.base.hands.HandSpec`.
"""

from __future__ import annotations

import math

import numpy as np
from pydrake.math import RollPitchYaw
from pydrake.systems.framework import Diagram, DiagramBuilder, LeafSystem
from pydrake.systems.primitives import (
    Adder,
    AffineSystem,
    Demultiplexer,
    Gain,
    MatrixGain,
    Saturation,
)

__all__ = ["PdHandDriver", "WristDriver", "HandDriverDiagram", "WristDriverDiagram",
           "actuated_order", "MEASURED_OUTPUTS"]


def actuated_order(plant, model_instance, joint_names) -> np.ndarray:
    """Permutation p with ``desired_q[i] = command[p[i]]``.

    The plant orders a model instance's desired-state input by its actuators'
    indices; the command vector follows ``joint_names``.
    """
    actuator_joints = [
        plant.get_joint_actuator(index).joint().name()
        for index in plant.GetJointActuatorIndices(model_instance)
    ]
    if sorted(actuator_joints) != sorted(joint_names):
        raise ValueError(
            f"actuated joints of the model {sorted(actuator_joints)} differ from the "
            f"expected {sorted(joint_names)}"
        )
    return np.array([list(joint_names).index(name) for name in actuator_joints], dtype=int)


def _joint_state_indices(plant, model_instance, joint_names):
    q_index, v_index = [], []
    for name in joint_names:
        joint = plant.GetJointByName(name, model_instance)
        if joint.num_positions() != 1:
            raise ValueError(f"joint {name!r} has {joint.num_positions()} positions, expected 1")
        q_index.append(joint.position_start())
        v_index.append(plant.num_positions() + joint.velocity_start())
    return np.array(q_index), np.array(v_index)


def _driver_setup(plant, model_instance, spec, initial_command, lower, upper,
                  max_joint_velocity, control_period):
    """What both hand drivers derive from their arguments: ``(nu, initial command clamped
    to the limits, lower, upper, rate-limit step per period, actuator order, q index,
    v index)``; a wrong-sized initial command is refused."""
    nu = len(spec.actuated_joint_names)
    initial_command = np.asarray(initial_command, dtype=float)
    if initial_command.shape != (nu,):
        raise ValueError(f"initial_command: expected {nu} values, got {initial_command.shape}")
    lower, upper = np.asarray(lower, dtype=float), np.asarray(upper, dtype=float)
    step = max_joint_velocity * control_period if max_joint_velocity > 0 else np.inf
    order = actuated_order(plant, model_instance, spec.actuated_joint_names)
    q_index, v_index = _joint_state_indices(plant, model_instance, spec.joint_names)
    return (nu, np.clip(initial_command, lower, upper), lower, upper, step, order,
            q_index, v_index)


class PdHandDriver(LeafSystem):
    """Tracks a joint position command with the plant's PD actuators.

    The system of the scenario's ``!SimHandDriver`` (its config, in
    :mod:`handle_drake.scenario`).

    The command is rate limited to ``max_joint_velocity`` (rad/s, 0 = off) and
    clamped to the actuated joints' limits in a periodic update every
    ``control_period`` seconds, like a hand's own joint controller. Until the
    ``position`` input is connected or given a value, the driver holds the
    initial command.

    Ports (``nu`` actuated joints, ``nq`` joints, in :class:`HandSpec` order):

    - input ``position`` (nu, rad): joint position command.
    - input ``plant_state`` (plant nq + nv): the plant's full state.
    - output ``desired_state`` (2 nu): ``[q_d; 0]`` in the plant's actuator order.
    - output ``position_commanded`` (nu, rad): the rate-limited command.
    - output ``position_measured`` (nq, rad), ``velocity_estimated`` (nq, rad/s),
      ``state_estimated`` (2 nq).
    """

    def __init__(self, plant, model_instance, spec, initial_command, lower, upper,
                 max_joint_velocity=4.0, control_period=0.002):
        super().__init__()
        (nu, self._initial, self._lower, self._upper, self._max_step, self._actuator_order,
         self._q_index, self._v_index) = _driver_setup(
            plant, model_instance, spec, initial_command, lower, upper, max_joint_velocity,
            control_period)
        nq = len(spec.joint_names)

        self._command_port = self.DeclareVectorInputPort("position", nu)
        self._plant_state_port = self.DeclareVectorInputPort(
            "plant_state", plant.num_positions() + plant.num_velocities()
        )
        # Group 0: the rate-limited command; group 1: the plant's desired state
        # [q_d; 0] in actuator order. Both change only in the periodic update,
        # and the outputs read the state directly (no Python call per step).
        self._command_state = self.DeclareDiscreteState(self._initial)
        self._desired_state = self.DeclareDiscreteState(self._desired(self._initial))
        self.DeclarePeriodicDiscreteUpdateEvent(control_period, 0.0, self._update_command)
        self.DeclareStateOutputPort("desired_state", self._desired_state)
        self.DeclareStateOutputPort("position_commanded", self._command_state)
        self.DeclareVectorOutputPort(
            "position_measured", nq,
            lambda context, out: out.SetFromVector(self._state(context)[self._q_index]),
        )
        self.DeclareVectorOutputPort(
            "velocity_estimated", nq,
            lambda context, out: out.SetFromVector(self._state(context)[self._v_index]),
        )
        self.DeclareVectorOutputPort(
            "state_estimated", 2 * nq,
            lambda context, out: out.SetFromVector(
                self._state(context)[np.concatenate([self._q_index, self._v_index])]
            ),
        )

    def get_command_input_port(self):
        return self._command_port

    def get_plant_state_input_port(self):
        return self._plant_state_port

    def _state(self, context):
        return self._plant_state_port.Eval(context)

    def target(self, context) -> np.ndarray:
        if not self._command_port.HasValue(context):
            return self._initial
        target = self._command_port.Eval(context)
        if not all(map(math.isfinite, target)):  # np.all(np.isfinite(.)) at a third of its cost
            # A non-finite command is ignored (the hand holds), never sent to the PD loops.
            return context.get_discrete_state(self._command_state).value()
        # np.clip's values (min(max(.)) is what it computes), without its wrapper's cost:
        # this runs every control period.
        return np.minimum(np.maximum(target, self._lower), self._upper)

    def _desired(self, command) -> np.ndarray:
        return np.concatenate([command[self._actuator_order], np.zeros(len(command))])

    def _update_command(self, context, discrete_state):
        current = context.get_discrete_state(self._command_state).value()
        step = np.minimum(np.maximum(self.target(context) - current, -self._max_step),
                          self._max_step)
        command = current + step
        discrete_state.set_value(self._command_state, command)
        desired = np.zeros(2 * len(command))  # [q_d; 0] (a new array: systems keep no
        desired[:len(command)] = command[self._actuator_order]  # scratch, contexts may run at once)
        discrete_state.set_value(self._desired_state, desired)

    def set_initial_command(self, context, command):
        """Sets the held command (for resets); clamped to the limits."""
        command = np.clip(np.asarray(command, dtype=float), self._lower, self._upper)
        context.SetDiscreteState(self._command_state, command)
        context.SetDiscreteState(self._desired_state, self._desired(command))


def _selection(rows, size) -> np.ndarray:
    """The 0/1 matrix ``S`` with ``(S u)[i] = u[rows[i]]`` (a zero row where ``rows[i]`` < 0)."""
    S = np.zeros((len(rows), size))
    for i, j in enumerate(rows):
        if j >= 0:
            S[i, j] = 1.0
    return S


def _held_state(builder, initial, period, name, A=None, B=None):
    """A discrete state ``x`` (default ``initial``) updated every ``period`` (from t = 0)
    and output: ``x_k+1 = A x_k + B u(t_k)``, ``y = x`` (an AffineSystem; by default
    A = 0, B = I: the input's value is held). A and B are 0/1 matrices with at most one 1
    a row, so each entry is an exact copy or an exact sum of two (A = B = I: ``x + u``)."""
    n = len(initial)
    A = np.zeros((n, n)) if A is None else A
    B = np.eye(n) if B is None else B
    hold = builder.AddNamedSystem(name, AffineSystem(
        A=A, B=B, f0=np.zeros(n), C=np.eye(n), D=np.zeros((n, B.shape[1])),
        y0=np.zeros(n), time_period=period))
    hold.configure_default_state(np.asarray(initial, dtype=float))
    return hold


MEASURED_OUTPUTS = ("position_measured", "velocity_estimated", "state_estimated")


def _export_measured(builder, size, q_index, v_index, read=MEASURED_OUTPUTS) -> None:
    """Exports a ``plant_state`` input (``size``) and ``state_estimated`` (its entries
    ``q_index`` then ``v_index``: one 0/1 MatrixGain, exact copies of finite values), split
    into ``position_measured`` and ``velocity_estimated`` by a Demultiplexer (copies): two
    systems for the three signals (each system in the diagram costs the simulator some
    work at every step, read or not). When ``read`` names one signal alone, one 0/1
    MatrixGain of its entries exports it (the same copies), and nothing else is built."""
    entries = {"position_measured": q_index, "velocity_estimated": v_index,
               "state_estimated": np.r_[q_index, v_index]}
    if len(set(read)) == 1:
        (name,) = set(read)
        _export_selections(builder, size, ((name, entries[name]),))
        return
    nq = len(q_index)
    state = builder.AddNamedSystem("state_estimated", MatrixGain(
        _selection(np.r_[q_index, v_index], size)))
    split = builder.AddNamedSystem("measured", Demultiplexer([nq, len(v_index)]))
    builder.Connect(state.get_output_port(), split.get_input_port())
    builder.ExportInput(state.get_input_port(), "plant_state")
    builder.ExportOutput(split.get_output_port(0), "position_measured")
    builder.ExportOutput(split.get_output_port(1), "velocity_estimated")
    builder.ExportOutput(state.get_output_port(), "state_estimated")


def _measured_read(measured) -> tuple:
    """:class:`HandDriverDiagram`'s ``measured``: True (all), False (none) or names."""
    if measured is True:
        return MEASURED_OUTPUTS
    if measured is False:
        return ()
    if isinstance(measured, str) or not all(isinstance(n, str) for n in measured):
        raise ValueError(f"measured: expected True, False or names of {MEASURED_OUTPUTS}, "
                         f"got {measured!r}")
    unknown = sorted(set(measured) - set(MEASURED_OUTPUTS))
    if unknown:
        raise ValueError(f"measured: {unknown[0]!r} is not one of {MEASURED_OUTPUTS}")
    return tuple(measured)


def _export_selections(builder, size, selections) -> None:
    """Exports a ``plant_state`` input (``size``) and, per ``(name, rows)``, an output
    ``name`` of its entries ``rows`` (a 0/1 MatrixGain: exact copies of finite values)."""
    first = True
    for name, rows in selections:
        select = builder.AddNamedSystem(name, MatrixGain(_selection(rows, size)))
        if first:
            builder.ExportInput(select.get_input_port(), "plant_state")
            first = False
        else:
            builder.ConnectInput("plant_state", select.get_input_port())
        builder.ExportOutput(select.get_output_port(), name)


class HandDriverDiagram(Diagram):
    """:class:`PdHandDriver`'s rate limit and clamp in Drake primitives: no Python call per
    control period. Same ports, same arithmetic in the same order, every ``control_period``:
    ``target = clamp(command, lower, upper)``, ``cmd += clamp(target - cmd, -s, s)``
    (``s = max_joint_velocity * control_period``), ``desired_state = [cmd[order]; 0]``
    (tested bit-identical to :class:`PdHandDriver` on the demo grasp).

    For commands that are connected and finite by construction (planned or validated
    before the run: the station's ``finite_commands``): unlike :class:`PdHandDriver` it
    does not hold on a non-finite command, and its ``position`` input must be connected.
    ``measured=False`` leaves out the measured-state selectors, with their outputs and
    the ``plant_state`` input (for a caller that reads none of them); a collection of
    :data:`MEASURED_OUTPUTS` names builds those read (one name alone: its one selector,
    the others absent).
    """

    def __init__(self, plant, model_instance, spec, initial_command, lower, upper,
                 max_joint_velocity=4.0, control_period=0.002, measured=True):
        super().__init__()
        read = _measured_read(measured)
        nu, initial, lower, upper, step, order, q_index, v_index = _driver_setup(
            plant, model_instance, spec, initial_command, lower, upper, max_joint_velocity,
            control_period)
        self._lower, self._upper = lower, upper
        nx = plant.num_positions() + plant.num_velocities()
        builder = DiagramBuilder()
        target = builder.AddNamedSystem("limits", Saturation(lower, upper))
        # cmd_k+1 = I cmd_k + I step_k (A = B = I: cmd + step, the Adder's sum)
        self._hold = _held_state(builder, initial, control_period, "command", A=np.eye(nu))
        negated = builder.AddNamedSystem("negated", Gain(-1.0, nu))
        error = builder.AddNamedSystem("error", Adder(2, nu))  # target + (-cmd)
        limited = builder.AddNamedSystem("rate_limit", Saturation(np.full(nu, -step),
                                                                  np.full(nu, step)))
        builder.Connect(self._hold.get_output_port(), negated.get_input_port())
        builder.Connect(target.get_output_port(), error.get_input_port(0))
        builder.Connect(negated.get_output_port(), error.get_input_port(1))
        builder.Connect(error.get_output_port(), limited.get_input_port())
        builder.Connect(limited.get_output_port(), self._hold.get_input_port())
        desired = builder.AddNamedSystem("desired", MatrixGain(
            _selection(np.r_[order, np.full(nu, -1)], nu)))
        builder.Connect(self._hold.get_output_port(), desired.get_input_port())
        builder.ExportInput(target.get_input_port(), "position")
        builder.ExportOutput(desired.get_output_port(), "desired_state")
        builder.ExportOutput(self._hold.get_output_port(), "position_commanded")
        if read:
            _export_measured(builder, nx, q_index, v_index, read)
        builder.BuildInto(self)

    def get_command_input_port(self):
        return self.GetInputPort("position")

    def get_plant_state_input_port(self):
        return self.GetInputPort("plant_state")

    def set_initial_command(self, context, command):
        """Sets the held command (for resets); clamped to the limits."""
        command = np.clip(np.asarray(command, dtype=float), self._lower, self._upper)
        self.GetMutableSubsystemContext(self._hold, context).SetDiscreteState(command)


WRIST_JOINTS = ("wrist_x", "wrist_y", "wrist_z", "wrist_yaw", "wrist_pitch", "wrist_roll")


# pose_to_wrist_joints as an index: joints[i] = pose6[_POSE6_TO_WRIST_JOINTS[i]].
_POSE6_TO_WRIST_JOINTS = np.array([0, 1, 2, 5, 4, 3])


def pose_to_wrist_joints(pose6: np.ndarray) -> np.ndarray:
    """``[x y z roll pitch yaw]`` -> wrist joint positions ``[x y z yaw pitch roll]``."""
    x, y, z, roll, pitch, yaw = pose6
    return np.array([x, y, z, yaw, pitch, roll])


class WristDriver(LeafSystem):
    """Drives the floating wrist (6 PD-actuated joints) to a commanded base pose.

    The command is sampled every ``control_period`` (a zero-order hold, like
    an arm's controller) and kept in discrete state, so the plant reads it
    without a Python call per time step.

    Ports:

    - input ``pose`` (6): ``[x y z roll pitch yaw]`` of the hand base in world,
      m and rad, ``R_WB = Rz(yaw) Ry(pitch) Rx(roll)``. Unconnected (or
      non-finite): holds the previous command (initially ``initial_pose6``).
    - input ``plant_state`` (plant nq + nv).
    - output ``desired_state`` (12): for the wrist's actuators.
    - output ``pose_measured`` (6): same convention as ``pose``.
    """

    def __init__(self, plant, model_instance, initial_pose6, control_period=0.002):
        super().__init__()
        initial = np.asarray(initial_pose6, dtype=float)
        if initial.shape != (6,):
            raise ValueError(f"initial pose: expected 6 values, got {initial.shape}")
        self._actuator_order = actuated_order(plant, model_instance, WRIST_JOINTS)
        # pose6 -> desired joint positions in one gather (pose_to_wrist_joints, then
        # actuator order).
        self._pose_to_desired = _POSE6_TO_WRIST_JOINTS[self._actuator_order]
        self._q_index, _ = _joint_state_indices(plant, model_instance, WRIST_JOINTS)
        self._pose_port = self.DeclareVectorInputPort("pose", 6)
        self._plant_state_port = self.DeclareVectorInputPort(
            "plant_state", plant.num_positions() + plant.num_velocities()
        )
        self._desired_state = self.DeclareDiscreteState(self._desired(initial))
        self.DeclarePeriodicDiscreteUpdateEvent(control_period, 0.0, self._update)
        self.DeclareStateOutputPort("desired_state", self._desired_state)
        self.DeclareVectorOutputPort("pose_measured", 6, self._calc_pose_measured)

    def get_pose_input_port(self):
        return self._pose_port

    def get_plant_state_input_port(self):
        return self._plant_state_port

    def _desired(self, pose6) -> np.ndarray:
        return np.concatenate([pose_to_wrist_joints(pose6)[self._actuator_order], np.zeros(6)])

    def _update(self, context, discrete_state):
        if not self._pose_port.HasValue(context):
            return
        pose = self._pose_port.Eval(context)
        if all(map(math.isfinite, pose)):
            desired = np.zeros(12)
            desired[:6] = pose[self._pose_to_desired]
            discrete_state.set_value(self._desired_state, desired)

    def _calc_pose_measured(self, context, out):
        x, y, z, yaw, pitch, roll = self._plant_state_port.Eval(context)[self._q_index]
        out.SetFromVector([x, y, z, roll, pitch, yaw])


class WristDriverDiagram(Diagram):
    """:class:`WristDriver` in Drake primitives: the pose sampled every ``control_period``
    into the desired state (the same permutation, exact copies), ``pose_measured`` from the
    plant state; no Python call per period. For a connected, finite ``pose`` command (see
    :class:`HandDriverDiagram`): it does not hold on a non-finite one. ``measured=False``
    leaves out ``pose_measured``'s selector and the ``plant_state`` input."""

    def __init__(self, plant, model_instance, initial_pose6, control_period=0.002,
                 measured: bool = True):
        super().__init__()
        initial = np.asarray(initial_pose6, dtype=float)
        if initial.shape != (6,):
            raise ValueError(f"initial pose: expected 6 values, got {initial.shape}")
        order = actuated_order(plant, model_instance, WRIST_JOINTS)
        q_index, _ = _joint_state_indices(plant, model_instance, WRIST_JOINTS)
        builder = DiagramBuilder()
        initial_desired = np.concatenate([pose_to_wrist_joints(initial)[order], np.zeros(6)])
        # the pose -> [joints in actuator order; 0] permutation as the hold's B (exact copies)
        hold = _held_state(builder, initial_desired, control_period, "desired", B=_selection(
            np.r_[_POSE6_TO_WRIST_JOINTS[order], np.full(6, -1)], 6))
        builder.ExportInput(hold.get_input_port(), "pose")
        builder.ExportOutput(hold.get_output_port(), "desired_state")
        # [x y z roll pitch yaw] from the joints [x y z yaw pitch roll]
        if measured:  # else no pose_measured and no plant_state input (nobody reads them)
            _export_selections(builder, plant.num_positions() + plant.num_velocities(),
                               (("pose_measured", q_index[[0, 1, 2, 5, 4, 3]]),))
        builder.BuildInto(self)

    def get_pose_input_port(self):
        return self.GetInputPort("pose")

    def get_plant_state_input_port(self):
        return self.GetInputPort("plant_state")


def rpy_pose6(X) -> np.ndarray:
    """A ``RigidTransform`` as ``[x y z roll pitch yaw]``."""
    rpy = RollPitchYaw(X.rotation()).vector()
    return np.concatenate([X.translation(), rpy])
