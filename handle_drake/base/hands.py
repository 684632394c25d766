"""The two hands of handle_drake and how to add them to a MultibodyPlant.

A :class:`HandSpec` names everything the rest of the library needs to know
about a hand without parsing it: joints in the order of the
``hand.position_measured`` port, actuated joints in command order, the
coupled joints, fingertip frames and tactile pads. Numbers that live in the
model file (joint limits, PD gains) are read from it on first use.

:func:`AddHand` parses a hand into a plant (SAP discrete solver), renames its
model instance and adds the coupler constraints that tie the unactuated
joints to their leaders (``q_follower = ratio * q_leader``). The Shadow hand's
distal ratio is a parameter: 1.0 for the C6 motor hand, 1.1 for the C5
air-muscle hand (seed report, section 2.1 and hand_kinematics.md).

The coupled joints also restrict the command: with ratio ``r`` the leader can
only reach ``follower_upper / r``; :func:`actuated_position_limits` gives the
effective range of each command entry.
"""

from __future__ import annotations

import math
import numbers
from dataclasses import dataclass
from functools import cache

import numpy as np

from handle_drake.base.models import add_package, model_path, package_url

__all__ = [
    "pad_surface_point",
    "HandSpec",
    "HAND_SPECS",
    "SHADOW_COUPLING_RATIO_C5",
    "SHADOW_COUPLING_RATIO_C6",
    "get_hand_spec",
    "AddHand",
    "actuated_to_joint_positions",
    "joint_to_actuated_positions",
    "actuated_position_limits",
    "joint_position_indices",
    "pad_geometry_ids",
    "EFFORT_LIMITS",
    "MENAGERIE_DEFAULT_EFFORT",
    "MENAGERIE_EFFORT_LIMITS",
    "effort_limit",
    "set_effort_limits",
]

SHADOW_COUPLING_RATIO_C6 = 1.0
SHADOW_COUPLING_RATIO_C5 = 1.1


@dataclass(frozen=True)
class HandSpec:
    """Names and structure of one hand model.

    Attributes:
        name: "shadow" or "barrett".
        model_relative_path: path of the SDFormat file inside ``models/``.
        model_name: the model's name in the file.
        base_body: the root link (what a mount welds or attaches).
        joint_names: all movable joints, in the order of ``hand.position_measured``.
        actuated_joint_names: the command vector's joints, in command order
            (equals the order of the model's actuators).
        couplings: ``(follower, leader, default_ratio)``; the follower is
            unactuated and held at ``ratio * leader`` by a coupler constraint.
        adjustable_couplings: followers whose ratio ``coupling_ratio`` of
            :func:`AddHand` replaces (Shadow: the four distal joints).
        fingertip_frames: one frame per finger at the fingertip.
        pad_geometries: ``(body, collision geometry)`` of the tactile pad of
            each finger, in the order of ``fingertip_frames``.
        fingers: the fingers' names, in the order of ``fingertip_frames``.
        finger_joints: per finger, the actuated joints that move it (command
            order); a joint shared by fingers (the Barrett spread, the Shadow
            wrist) belongs to none. The one finger -> joints map of the project.
        closing_joints: per finger, those of its joints that press its
            fingertip onto an object (flexion, not abduction).
    """

    name: str
    model_relative_path: str
    model_name: str
    base_body: str
    joint_names: tuple[str, ...]
    actuated_joint_names: tuple[str, ...]
    couplings: tuple[tuple[str, str, float], ...]
    adjustable_couplings: tuple[str, ...]
    fingertip_frames: tuple[str, ...]
    pad_geometries: tuple[tuple[str, str], ...]
    fingers: tuple[str, ...] = ()
    finger_joints: tuple[tuple[str, ...], ...] = ()
    closing_joints: tuple[tuple[str, ...], ...] = ()

    def finger_command_indices(self) -> list[list[int]]:
        """Per finger, the indices of its joints in the command vector."""
        names = list(self.actuated_joint_names)
        return [[names.index(j) for j in joints] for joints in self.finger_joints]

    @property
    def num_joints(self) -> int:
        return len(self.joint_names)

    @property
    def num_actuated(self) -> int:
        return len(self.actuated_joint_names)

    @property
    def joint_lower_limits(self) -> np.ndarray:
        """Lower position limits (rad) in ``joint_names`` order, read from the model."""
        return _model_data(self.name)["lower"].copy()

    @property
    def joint_upper_limits(self) -> np.ndarray:
        """Upper position limits (rad) in ``joint_names`` order, read from the model."""
        return _model_data(self.name)["upper"].copy()

    @property
    def pd_gains(self) -> tuple[np.ndarray, np.ndarray]:
        """``(kp, kd)`` of the model's PD actuators in command order (N*m/rad, N*m*s/rad)."""
        data = _model_data(self.name)
        return data["kp"].copy(), data["kd"].copy()

    @property
    def effort_limits(self) -> np.ndarray:
        """Actuator effort limits (N*m) in command order."""
        return _model_data(self.name)["effort"].copy()

    def coupling_ratios(
        self, coupling_ratio: float | None = None
    ) -> tuple[tuple[str, str, float], ...]:
        """The couplings with ``coupling_ratio`` applied to the adjustable ones."""
        if coupling_ratio is None:
            return self.couplings
        ratio = _check_ratio(coupling_ratio)
        if not self.adjustable_couplings:
            raise ValueError(
                f"coupling_ratio: the {self.name} hand's couplings are fixed by its mechanism; "
                f"expected None, got {coupling_ratio!r}"
            )
        return tuple(
            (follower, leader, ratio if follower in self.adjustable_couplings else default)
            for follower, leader, default in self.couplings
        )


def _shadow_spec() -> HandSpec:
    fingers = ("FF", "MF", "RF", "LF")
    joints = ["WRJ2", "WRJ1"]
    actuated = ["WRJ2", "WRJ1"]
    for f in fingers:
        if f == "LF":
            joints.append("LFJ5")
            actuated.append("LFJ5")
        joints += [f"{f}J4", f"{f}J3", f"{f}J2", f"{f}J1"]
        actuated += [f"{f}J4", f"{f}J3", f"{f}J2"]
    thumb = ["THJ5", "THJ4", "THJ3", "THJ2", "THJ1"]
    joints += thumb
    actuated += thumb
    return HandSpec(
        name="shadow",
        model_relative_path="shadow_hand/shadow_hand_right.sdf",
        model_name="shadow_hand",
        base_body="forearm",
        joint_names=tuple(joints),
        actuated_joint_names=tuple(actuated),
        couplings=tuple((f"{f}J1", f"{f}J2", SHADOW_COUPLING_RATIO_C6) for f in fingers),
        adjustable_couplings=tuple(f"{f}J1" for f in fingers),
        fingertip_frames=("fftip", "mftip", "rftip", "lftip", "thtip"),
        pad_geometries=tuple((f"{f}distal", f"{f}tip_pad") for f in ("ff", "mf", "rf", "lf", "th")),
        fingers=("ff", "mf", "rf", "lf", "th"),
        # The distal J1 follows J2 (coupled): J4..J2 (LFJ5 too) move a finger.
        finger_joints=tuple(tuple(n for n in actuated if n.startswith(f))
                            for f in (*fingers, "TH")),
        closing_joints=(("FFJ3", "FFJ2"), ("MFJ3", "MFJ2"), ("RFJ3", "RFJ2"), ("LFJ3", "LFJ2"),
                        ("THJ1",)),
    )


def _barrett_spec() -> HandSpec:
    return HandSpec(
        name="barrett",
        model_relative_path="barrett_hand/bh8_280.sdf",
        model_name="barrett_hand",
        base_body="bh_base",
        joint_names=(
            "f1_spread",
            "f1_prox",
            "f1_dist",
            "f2_spread",
            "f2_prox",
            "f2_dist",
            "f3_prox",
            "f3_dist",
        ),
        actuated_joint_names=("f1_spread", "f1_prox", "f2_prox", "f3_prox"),
        couplings=(
            ("f2_spread", "f1_spread", 1.0),
            ("f1_dist", "f1_prox", 1.0 / 3.0),
            ("f2_dist", "f2_prox", 1.0 / 3.0),
            ("f3_dist", "f3_prox", 1.0 / 3.0),
        ),
        adjustable_couplings=(),
        fingertip_frames=("f1_tip", "f2_tip", "f3_tip"),
        pad_geometries=(
            ("f1_distal", "f1_tip_pad"),
            ("f2_distal", "f2_tip_pad"),
            ("f3_distal", "f3_tip_pad"),
        ),
        # Named as on the BH8-280 (Barrett's D-H table, the hand's pucks F1 F2 F3
        # spread, libbarrett, GraspIt, OpenRAVE): f1 is the finger on the palm's
        # x < 0 side, f2 on x > 0, f3 the fixed one on +y (models/barrett_hand),
        # so a setpoint for ``f1_prox`` moves the same physical finger on the CAN
        # hand as in simulation (tests/can_hand/test_can_finger_sides.py).
        fingers=("f1", "f2", "f3"),
        # The spread turns F1 and F2 together: it belongs to no single finger.
        finger_joints=(("f1_prox",), ("f2_prox",), ("f3_prox",)),
        closing_joints=(("f1_prox",), ("f2_prox",), ("f3_prox",)),
    )


HAND_SPECS: dict[str, HandSpec] = {"shadow": _shadow_spec(), "barrett": _barrett_spec()}


def get_hand_spec(name: str) -> HandSpec:
    """The :class:`HandSpec` named ``name``; ValueError naming the valid names otherwise."""
    if not isinstance(name, str) or name not in HAND_SPECS:
        raise ValueError(f"unknown hand {name!r}; expected one of {sorted(HAND_SPECS)}")
    return HAND_SPECS[name]


def _check_ratio(ratio) -> float:
    if isinstance(ratio, bool) or not isinstance(ratio, numbers.Real):
        raise TypeError(f"coupling_ratio: expected a real number, got {type(ratio).__name__}")
    value = float(ratio)
    if not math.isfinite(value) or value <= 0.0:
        raise ValueError(f"coupling_ratio: expected a finite number > 0, got {ratio!r}")
    return value


def _check_sap(plant) -> None:
    from pydrake.multibody.plant import DiscreteContactSolver

    if (
        plant.time_step() <= 0.0
        or plant.get_discrete_contact_solver() != DiscreteContactSolver.kSap
    ):
        raise ValueError(
            "plant: coupler constraints and PD actuators need a discrete plant with the SAP "
            "solver; build it with MultibodyPlantConfig(time_step>0, "
            'discrete_contact_approximation="sap")'
        )


def AddHand(
    plant,
    kind: str,
    coupling_ratio: float | None = None,
    parser=None,
    model_instance_name: str = "hand",
):
    """Parses hand ``kind`` into ``plant`` and adds its coupler constraints.

    Must be called before ``plant.Finalize()``. The plant must be discrete
    with the SAP solver (couplers and PD actuators need it).

    Args:
        plant: a MultibodyPlant (not finalized, SAP).
        kind: "shadow" or "barrett".
        coupling_ratio: ratio of the adjustable couplings (Shadow ``xFJ1 =
            ratio * xFJ2``; default 1.0, C5 hand 1.1). Must be None for hands
            whose couplings are fixed (Barrett).
        parser: a Parser for ``plant`` (e.g. one with a DiagramBuilder); a new
            one is made when None. Its auto-renaming setting is restored.
        model_instance_name: name of the new model instance.

    Returns:
        The hand's ModelInstanceIndex. Its base body is free; weld or attach
        ``spec.base_body`` before finalizing.
    """
    from pydrake.multibody.parsing import Parser
    from pydrake.multibody.tree import JointActuatorIndex

    spec = get_hand_spec(kind)
    couplings = spec.coupling_ratios(coupling_ratio)
    if not isinstance(model_instance_name, str) or not model_instance_name:
        raise ValueError(
            f"model_instance_name: expected a non-empty string, got {model_instance_name!r}"
        )
    if plant.is_finalized():
        raise ValueError("plant: AddHand must be called before plant.Finalize()")
    _check_sap(plant)
    if plant.HasModelInstanceNamed(model_instance_name):
        raise ValueError(
            f"model_instance_name: the plant already has a model named {model_instance_name!r}"
        )
    if parser is None:
        parser = Parser(plant)
    elif parser.plant() is not plant:
        raise ValueError("parser: expected a Parser of the given plant, got one of another plant")
    add_package(parser)
    auto_renaming = parser.GetAutoRenaming()
    parser.SetAutoRenaming(True)  # a second hand's "shadow_hand" must not clash before renaming
    try:
        instances = parser.AddModelsFromUrl(package_url(spec.model_relative_path))
    finally:
        parser.SetAutoRenaming(auto_renaming)
    if len(instances) != 1:
        raise RuntimeError(f"{spec.model_relative_path}: expected one model, got {len(instances)}")
    instance = instances[0]
    plant.RenameModelInstance(instance, model_instance_name)

    # GetJointActuatorIndices(instance) is only filled in at Finalize().
    actuators = [
        plant.get_joint_actuator(JointActuatorIndex(i)) for i in range(plant.num_actuators())
    ]
    actuated = [a.joint().name() for a in actuators if a.model_instance() == instance]
    if tuple(actuated) != spec.actuated_joint_names:
        raise RuntimeError(
            f"{spec.model_relative_path}: actuators {actuated} do not match the command order "
            f"{list(spec.actuated_joint_names)}; regenerate the model"
        )
    for follower, leader, ratio in couplings:
        plant.AddCouplerConstraint(
            joint0=plant.GetJointByName(follower, instance),
            joint1=plant.GetJointByName(leader, instance),
            gear_ratio=ratio,
            offset=0.0,
        )
    return instance


# ---------------------------------------------------------------------------
# Command <-> joint vectors


def _as_vector(name: str, value, size: int) -> np.ndarray:
    array = np.asarray(value, dtype=float)
    if array.ndim != 1 or array.shape[0] != size:
        raise ValueError(f"{name}: expected a vector of size {size}, got shape {array.shape}")
    if not np.all(np.isfinite(array)):
        raise ValueError(f"{name}: expected finite values, got {array}")
    return array


def actuated_to_joint_positions(
    spec: HandSpec, q_actuated, coupling_ratio: float | None = None
) -> np.ndarray:
    """Full joint vector (``spec.joint_names`` order) from a command (actuated order).

    Each follower is set to ``ratio * leader``, so the result satisfies the
    coupler constraints exactly (useful for initial conditions and synergies).
    """
    q_actuated = _as_vector("q_actuated", q_actuated, spec.num_actuated)
    value = dict(zip(spec.actuated_joint_names, q_actuated, strict=True))
    for follower, leader, ratio in spec.coupling_ratios(coupling_ratio):
        value[follower] = ratio * value[leader]
    return np.array([value[name] for name in spec.joint_names])


def joint_to_actuated_positions(spec: HandSpec, q) -> np.ndarray:
    """The command entries (actuated order) of a full joint vector."""
    q = _as_vector("q", q, spec.num_joints)
    index = {name: i for i, name in enumerate(spec.joint_names)}
    return np.array([q[index[name]] for name in spec.actuated_joint_names])


def actuated_position_limits(spec: HandSpec, coupling_ratio: float | None = None):
    """``(lower, upper)`` of each command entry such that leader and followers stay in limits.

    A leader with follower ratio ``r > 0`` is limited to
    ``[max(lo_L, lo_F / r), min(hi_L, hi_F / r)]``.
    """
    index = {name: i for i, name in enumerate(spec.joint_names)}
    lower_all, upper_all = spec.joint_lower_limits, spec.joint_upper_limits
    lower = {name: lower_all[index[name]] for name in spec.actuated_joint_names}
    upper = {name: upper_all[index[name]] for name in spec.actuated_joint_names}
    for follower, leader, ratio in spec.coupling_ratios(coupling_ratio):
        lower[leader] = max(lower[leader], lower_all[index[follower]] / ratio)
        upper[leader] = min(upper[leader], upper_all[index[follower]] / ratio)
    names = spec.actuated_joint_names
    return np.array([lower[n] for n in names]), np.array([upper[n] for n in names])


# ---------------------------------------------------------------------------
# Plant helpers


def joint_position_indices(plant, model_instance, spec: HandSpec) -> np.ndarray:
    """Indices into the plant's position vector of ``spec.joint_names`` (finalized plant)."""
    return np.array(
        [plant.GetJointByName(name, model_instance).position_start() for name in spec.joint_names],
        dtype=int,
    )


def pad_geometry_ids(plant, model_instance, spec: HandSpec, inspector) -> list:
    """GeometryIds of the tactile pads (finger order of ``spec.pad_geometries``).

    ``inspector`` is a SceneGraphInspector (``scene_graph.model_inspector()``).
    """
    ids = []
    for body_name, geometry_name in spec.pad_geometries:
        body = plant.GetBodyByName(body_name, model_instance)
        found = [
            gid
            for gid in plant.GetCollisionGeometriesForBody(body)
            if inspector.GetName(gid).split("::")[-1] == geometry_name
        ]
        if len(found) != 1:
            raise RuntimeError(
                f"pad {geometry_name!r} on {body_name!r}: expected 1 geometry, got {len(found)}"
            )
        ids.append(found[0])
    return ids


# The hand's actuator effort limits (N m) in MuJoCo Menagerie's Shadow hand model
# (google-deepmind/mujoco_menagerie, shadow_hand/right_hand.xml, made with Shadow Robot:
# the position actuators' forcerange): 1 N m by default (the class "right_hand"), the
# wrist 10 (WRJ2) and 5 (WRJ1), the thumb base 3 (THJ5) and 2 (THJ4). The fingers' J0
# tendon (J1 + J2) is one 1 N m actuator there; here the J2 actuator (J1 = J2 by the
# coupler). The SDF's own limits are sr_description's sheet (2 N m for the finger joints;
# models/shadow_hand/README.md, "Effort limits").
MENAGERIE_EFFORT_LIMITS = {"WRJ2": 10.0, "WRJ1": 5.0, "THJ5": 3.0, "THJ4": 2.0}
MENAGERIE_DEFAULT_EFFORT = 1.0
EFFORT_LIMITS = ("sheet", "menagerie")


def effort_limit(name: str, limits: str) -> float | None:
    """The effort limit (N m) of actuated joint ``name`` under ``limits`` ("menagerie"), or
    None ("sheet": the model file's own)."""
    if limits == "sheet":
        return None
    return MENAGERIE_EFFORT_LIMITS.get(name, MENAGERIE_DEFAULT_EFFORT)


def set_effort_limits(plant, hand, limits: str, scale: float = 1.0) -> None:
    """Sets the effort limit of every actuator of model instance ``hand`` of an unfinalized
    plant: :func:`effort_limit` under ``limits`` (the model file's own for "sheet") times
    ``scale`` in (0, 1] (perturbed physics)."""
    if limits not in EFFORT_LIMITS:
        raise ValueError(f"effort_limits: expected one of {EFFORT_LIMITS}, got {limits!r}")
    if not (math.isfinite(scale) and 0 < scale <= 1):
        raise ValueError(f"effort_scale: expected a value in (0, 1], got {scale!r}")
    # (before Finalize the per-instance query lists nothing: filter all of them)
    for i in plant.GetJointActuatorIndices():
        actuator = plant.get_joint_actuator(i)
        if actuator.model_instance() != hand:
            continue
        value = effort_limit(actuator.joint().name(), limits)
        if value is None:
            value = actuator.effort_limit()
        if value != actuator.effort_limit() or scale != 1.0:
            actuator.set_effort_limit(value * scale)



@cache
def _model_data(name: str) -> dict:
    """Limits, gains and efforts read from the model file (a throwaway plant)."""
    from pydrake.multibody.parsing import Parser
    from pydrake.multibody.plant import MultibodyPlant

    spec = get_hand_spec(name)
    plant = MultibodyPlant(time_step=0.0)
    parser = Parser(plant)
    add_package(parser)
    instance = parser.AddModels(model_path(spec.model_relative_path))[0]
    joints = [plant.GetJointByName(n, instance) for n in spec.joint_names]
    actuators = [plant.GetJointActuatorByName(n, instance) for n in spec.actuated_joint_names]
    gains = [a.get_controller_gains() for a in actuators]
    data = {
        "lower": np.array([j.position_lower_limits()[0] for j in joints]),
        "upper": np.array([j.position_upper_limits()[0] for j in joints]),
        "kp": np.array([g.p for g in gains]),
        "kd": np.array([g.d for g in gains]),
        "effort": np.array([a.effort_limit() for a in actuators]),
    }
    for array in data.values():
        array.setflags(write=False)
    return data


def pad_surface_point(u, v, radius: float) -> tuple[np.ndarray, np.ndarray]:
    """Points (n, 3) at surface coordinates ``(u, v)`` (m) of a tactile pad and the outward
    normals there, in the pad's frame P: a flat pad (``radius`` 0) lies in P's ``z = 0``
    plane; a skin (``radius`` r > 0) is wrapped around a cylinder of radius r whose axis
    is P's ``y`` line through ``(0, 0, -r)``, ``u`` its arc length. The one definition
    of a pad's surface for the taxel sensor (``devices/taxels``) and the reactive grasp's
    centre of pressure (``systems/reactive_grasp``)."""
    u, v = np.atleast_1d(np.asarray(u, float)), np.atleast_1d(np.asarray(v, float))
    if radius <= 0.0:
        return (np.column_stack([u, v, np.zeros_like(u)]),
                np.tile([0.0, 0.0, 1.0], (len(u), 1)))
    a = u / radius
    n = np.column_stack([np.sin(a), np.zeros_like(a), np.cos(a)])
    p = radius * n
    p[:, 2] -= radius
    p[:, 1] = v
    return p, n
