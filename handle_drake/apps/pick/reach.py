"""Arm configurations that reach a planned hand pose: Drake's ``InverseKinematics``
with the arm's joint limits and collision avoidance, and a collision-checked
joint-space path between two of them.

:class:`ArmReach` builds, once per scenario, a plant of the arm with the hand
bolted to its flange, the table, the sorting box and the scene's objects
(welded where they stand: the IK moves only the arm). :meth:`ArmReach.solve`
finds arm joints that put the hand's base at a target pose (position within
``position_tolerance``, orientation within ``angle_tolerance``) with the hand's
fingers at a given posture, every collision pair of the robot at least
``clearance`` apart (objects named in ``ignore`` excepted: the object being
grasped is touched on purpose), starting from a seed (the previous
configuration, so consecutive waypoints stay on one IK branch).

An arm with fewer than six joints (Shadow's 4-DOF arm of the Paris platform)
cannot put the hand's base at an arbitrary pose. Its IK frees the hand's wrist
joints (:func:`wrist_joints`: the hand joints every finger hangs from; the
Shadow hand's WRJ2 and WRJ1) within their limits and asks for the palm (the
body after them) where the plan's posture would put it: the hand's base may
then move, the palm and fingers are where the grasp wants them.
:attr:`IkResult.q_hand` holds the hand's joints with the wrist so solved. Six
joints (four and the wrist's two) reach few of the grasp planner's poses exactly
(8 of 24 pre-grasp and grasp poses of three classes on a sphere in a Paris
layout; 17 of 24 with the symmetry below: docs/results/paris.md), so
such an arm may also use the grasped object's symmetry (``symmetry=(kind,
p_BO)``, the object's centre in the hand base frame): a sphere's grasp is the
same turned about its centre (up to :data:`SPHERE_TURN` rad from the plan), an
upright cuboid's turned about the vertical through its centre (up to
:data:`CUBOID_TURN` rad); the centre keeps its place in the hand.
"""

from __future__ import annotations

import dataclasses as dc
import itertools
import time

import numpy as np
from pydrake.math import RigidTransform
from pydrake.multibody.inverse_kinematics import InverseKinematics
from pydrake.multibody.plant import AddMultibodyPlant, MultibodyPlantConfig
from pydrake.solvers import Solve
from pydrake.systems.framework import DiagramBuilder

from handle_drake.base.hands import AddHand, get_hand_spec
from handle_drake.devices.arm.model import ARM_INSTANCE, AddArm, get_arm_spec
from handle_drake.geometry.objects import AddObject, AddTable
from handle_drake.scene.config import initial_pose, scene_objects, spec_of
from handle_drake.scene.plant import AddSortingBox

__all__ = ["ArmReach", "IkResult", "SPHERE_TURN", "CUBOID_TURN", "wrist_joints",
           "BUDGET_SPENT", "IK_ITERATIONS", "COLLISION_IK_ITERATIONS"]

#: :attr:`IkResult.message` of a solve refused because ``ArmReach.ik_limit`` is reached.
BUDGET_SPENT = "the IK budget is spent"

#: Largest turn (rad) of a sphere's grasp about its centre an arm with fewer than six
#: joints may take instead of the planned one (ours: the fingers' approach stays
#: within 30 deg of the planner's, whose table clearance the IK checks again).
SPHERE_TURN = 0.5
#: The same for an upright cuboid, about the vertical through its centre (ours:
#: the fingers stay on the faces the grasp planned within 10 deg).
CUBOID_TURN = 0.17
#: SNOPT major iterations of one IK stage: the kinematic problem alone, and the one with
#: the minimum-distance constraint (an arm of six joints or more; fewer: the kinematic
#: limit). Measured on the 564 IK solves of the pick plans of development scenes
#: (Hamburg seeds 0-35 but 7, and 39, 40, 49, 50, perceived; the shape sorter's 600-619
#: each kind, true poses),
#: each solved again with fewer iterations: the collision stage's 5 successes of 53 all
#: converged within 20 iterations (3 lost at 10), its 48 failures ran to the limit
#: (0.1-2.9 s each at 100: 22.1 s of the 26.6 s all 564 solves took); at 20 that
#: stage took 5.1 s and found the same 5. The kinematic stage's successes need up to
#: 100 (8 of 67 lost at 50), its failures are cheap (1.4 s of 4.2 s).
IK_ITERATIONS = 100
COLLISION_IK_ITERATIONS = 20


@dc.dataclass
class IkResult:
    q: np.ndarray | None  # arm joints (rad), None when not found
    seconds: float
    position_error: float = float("nan")  # m
    angle_error: float = float("nan")  # rad
    message: str = ""
    # The hand's joints with the wrist joints solved (arms with fewer than six joints).
    q_hand: np.ndarray | None = None

    @property
    def ok(self) -> bool:
        return self.q is not None


class ArmReach:
    """IK for the scenario's ``!Arm`` (see module doc)."""

    def __init__(self, scenario, ignore: tuple[str, ...] = ()):

        mount = scenario.hand.mount
        self.spec = get_arm_spec(mount.kind)
        self.hand_spec = get_hand_spec(scenario.hand.kind)
        self.coupling_ratio = scenario.hand.coupling_ratio
        builder = DiagramBuilder()
        plant, scene_graph = AddMultibodyPlant(
            MultibodyPlantConfig(time_step=0.001, discrete_contact_approximation="sap"),
            builder)
        self.hand = AddHand(plant, scenario.hand.kind, coupling_ratio=scenario.hand.coupling_ratio)
        base = plant.GetBodyByName(self.hand_spec.base_body, self.hand).body_frame()
        self.arm = AddArm(plant, mount, base, name=ARM_INSTANCE)
        if scenario.table is not None:

            AddTable(plant, top_height=scenario.table.top_height,
                     size=(scenario.table.size_x, scenario.table.size_y))
        if scenario.sorting_box is not None:
            AddSortingBox(plant, scenario)

        self.objects = {}
        for name, o in scene_objects(scenario):
            if name in ignore:
                continue
            instance = AddObject(plant, spec_of(o), name=name)
            body = plant.get_body(plant.GetBodyIndices(instance)[0])
            plant.WeldFrames(plant.world_frame(), body.body_frame(),
                             initial_pose(o, scenario.table))
            self.objects[name] = instance
        plant.Finalize()
        # The hand's own posture is the grasp planner's (it checks its fingers):
        # only the robot against the world, and the arm against itself and the hand.
        from pydrake.geometry import CollisionFilterDeclaration, GeometrySet

        hand_bodies = [plant.get_body(i) for i in plant.GetBodyIndices(self.hand)]
        hand_set = GeometrySet([plant.GetBodyFrameIdOrThrow(b.index()) for b in hand_bodies])
        scene_graph.collision_filter_manager().Apply(
            CollisionFilterDeclaration().ExcludeWithin(hand_set))
        self.plant = plant
        self.diagram = builder.Build()
        self.context = self.diagram.CreateDefaultContext()
        self.plant_context = plant.GetMyMutableContextFromRoot(self.context)
        self.base_frame = plant.GetFrameByName(self.hand_spec.base_body, self.hand)
        self._arm_q = np.array([plant.GetJointByName(n, self.arm).position_start()
                                for n in self.spec.joint_names])
        self._hand_q = np.array([plant.GetJointByName(n, self.hand).position_start()
                                 for n in self.hand_spec.joint_names])
        self.query_port = plant.get_geometry_query_input_port()
        # Fewer than six arm joints: the hand's wrist joints join the IK (module doc).
        self.free_hand_joints = () if len(self.spec.joint_names) >= 6 else wrist_joints(
            plant, self.hand, self.hand_spec)
        self._free_in_hand = np.array([self.hand_spec.joint_names.index(n)
                                       for n in self.free_hand_joints], dtype=int)
        self.target_frame = self.base_frame
        # Work done (:meth:`solve` calls, each one or two SNOPT solves of at most 100
        # major iterations) and the limit a planner may set on it (None: none): a solve
        # asked for past ``ik_limit`` fails at once with :data:`BUDGET_SPENT`.
        self.ik_solves = 0
        self.ik_limit: int | None = None
        if self.free_hand_joints:
            last = plant.GetJointByName(self.free_hand_joints[-1], self.hand)
            self.target_frame = last.child_body().body_frame()

    def positions(self, q_arm, q_hand) -> np.ndarray:
        q = np.zeros(self.plant.num_positions())
        q[self._arm_q] = q_arm
        q[self._hand_q] = q_hand
        return q

    def min_distance(self, q_arm, q_hand, max_distance: float = 0.05) -> float:
        """Smallest signed distance (m) between robot geometry and anything else
        (or within the robot), up to ``max_distance``."""
        self.plant.SetPositions(self.plant_context, self.positions(q_arm, q_hand))
        query = self.query_port.Eval(self.plant_context)
        pairs = query.ComputeSignedDistancePairwiseClosestPoints(max_distance)
        return min((p.distance for p in pairs), default=max_distance)

    def palm_in_base(self, q_hand) -> RigidTransform:
        """The IK's target frame (the palm for an arm with fewer than six joints, else
        the hand's base) in the hand's base frame at the hand joints ``q_hand``."""
        self.plant.SetPositions(self.plant_context,
                                self.positions(np.zeros(len(self._arm_q)), q_hand))
        return self.target_frame.CalcPose(self.plant_context, self.base_frame)

    def hand_pose(self, q_arm, q_hand=None) -> RigidTransform:
        q_hand = np.zeros(len(self._hand_q)) if q_hand is None else q_hand
        self.plant.SetPositions(self.plant_context, self.positions(q_arm, q_hand))
        return self.base_frame.CalcPoseInWorld(self.plant_context)

    def solve(self, X_WB: RigidTransform, q_seed, q_hand, clearance: float = 0.003,
              position_tolerance: float = 0.002, angle_tolerance: float = 0.02,
              collision: bool = True, symmetry=None) -> IkResult:
        """Arm joints putting the hand base at ``X_WB`` (see the module doc).

        Two stages: the kinematic problem alone (fast; when it has no solution
        from this seed, neither has the full one), then, seeded by its answer,
        with the minimum-distance constraint."""
        start = time.perf_counter()
        if self.budget_spent():
            return IkResult(None, 0.0, message=BUDGET_SPENT)
        self.ik_solves += 1
        q_hand = np.asarray(q_hand, dtype=float)
        seed = self.positions(q_seed, q_hand)
        X_target = X_WB
        if self.free_hand_joints:  # the palm where the posture puts it (module doc)
            self.plant.SetPositions(self.plant_context, seed)
            X_target = X_WB @ self.target_frame.CalcPose(self.plant_context, self.base_frame)
        pivot = None
        if self.free_hand_joints and symmetry is not None and symmetry[0] in (
                "sphere", "cuboid"):
            # The object's centre in the palm frame, and where it is in world.
            kind, p_BO = symmetry
            X_BP = X_WB.inverse() @ X_target
            pivot = (kind, X_BP.inverse() @ np.asarray(p_BO, dtype=float),
                     X_WB @ np.asarray(p_BO, dtype=float))
        result, q = self._solve(X_target, seed, q_hand, None, position_tolerance,
                                angle_tolerance, pivot)
        if result.is_success() and collision:
            seed = result.GetSolution(q)
            if self.min_distance(seed[self._arm_q], seed[self._hand_q], 0.03) < clearance:
                result, q = self._solve(X_target, seed, q_hand, clearance, position_tolerance,
                                        angle_tolerance, pivot)
        seconds = time.perf_counter() - start
        if not result.is_success():
            return IkResult(None, seconds, message=f"IK failed ({result.get_solver_id().name()})")
        solution = result.GetSolution(q)
        q_arm = solution[self._arm_q]
        solved_hand = solution[self._hand_q] if self.free_hand_joints else None
        self.plant.SetPositions(self.plant_context, self.positions(
            q_arm, q_hand if solved_hand is None else solved_hand))
        X = self.target_frame.CalcPoseInWorld(self.plant_context)
        return IkResult(q_arm, seconds,
                        float(np.linalg.norm(X.translation() - X_target.translation())),
                        float(X.rotation().InvertAndCompose(X_target.rotation()).ToAngleAxis()
                              .angle()), q_hand=solved_hand)

    def budget_spent(self) -> bool:
        """Whether :attr:`ik_solves` has reached :attr:`ik_limit`."""
        return self.ik_limit is not None and self.ik_solves >= self.ik_limit

    def _solve(self, X_WB, seed, q_hand, clearance, position_tolerance, angle_tolerance,
               pivot=None):
        from pydrake.solvers import SnoptSolver

        plant = self.plant
        ik = InverseKinematics(plant, self.plant_context, with_joint_limits=True)
        q = ik.q()
        prog = ik.get_mutable_prog()
        p = X_WB.translation()
        frame = self.target_frame
        if pivot is None:
            ik.AddPositionConstraint(frame, np.zeros(3), plant.world_frame(),
                                     p - position_tolerance, p + position_tolerance)
            ik.AddOrientationConstraint(plant.world_frame(), X_WB.rotation(), frame,
                                        _identity(), angle_tolerance)
        else:  # the object's symmetry (module doc)
            kind, p_PO, p_WO = pivot
            ik.AddPositionConstraint(frame, p_PO, plant.world_frame(),
                                     p_WO - position_tolerance, p_WO + position_tolerance)
            turn = SPHERE_TURN if kind == "sphere" else CUBOID_TURN
            ik.AddOrientationConstraint(plant.world_frame(), X_WB.rotation(), frame,
                                        _identity(), turn)
            if kind == "cuboid":  # about the vertical only
                up_P = X_WB.rotation().inverse() @ np.array([0.0, 0.0, 1.0])
                ik.AddAngleBetweenVectorsConstraint(plant.world_frame(), [0.0, 0.0, 1.0],
                                                    frame, up_P, 0.0, angle_tolerance)
        fixed = np.setdiff1d(np.arange(len(self._hand_q)), self._free_in_hand)
        prog.AddBoundingBoxConstraint(q_hand[fixed], q_hand[fixed], q[self._hand_q[fixed]])
        moved = np.concatenate([self._arm_q, self._hand_q[self._free_in_hand]])
        prog.AddQuadraticErrorCost(np.eye(len(moved)), seed[moved], q[moved])
        if clearance is not None:
            ik.AddMinimumDistanceLowerBoundConstraint(clearance, 0.03)
        # Bounded effort: a pose out of reach fails in a fraction of a second.
        iterations = COLLISION_IK_ITERATIONS if clearance is not None and \
            not self.free_hand_joints else IK_ITERATIONS
        prog.SetSolverOption(SnoptSolver.id(), "Major iterations limit", iterations)
        return Solve(prog, seed), q

    def solve_from_seeds(self, X_WB: RigidTransform, seeds, q_hand, tries: int = 4,
                         rng=None, **options) -> IkResult:
        """:meth:`solve` from each seed (once each: repeats are skipped), then from
        ``tries`` random configurations within the limits; the first success (total
        time in ``seconds``)."""
        rng = np.random.default_rng(0) if rng is None else rng
        given = []
        for s in seeds:  # a seed equal to an earlier one would repeat its solve
            s = np.asarray(s, dtype=float)
            if not any(np.array_equal(s, t) for t in given):
                given.append(s)
        seeds = given + [rng.uniform(self.spec.lower, self.spec.upper) for _ in range(tries)]
        total = 0.0
        result = IkResult(None, 0.0, message="no seed")
        for seed in seeds:
            result = self.solve(X_WB, seed, q_hand, **options)
            total += result.seconds
            if result.ok or result.message == BUDGET_SPENT:
                break
        result.seconds = total
        return result

    def path_is_free(self, q_from, q_to, q_hand, step: float = 0.02,
                     clearance: float = 0.0) -> bool:
        """Whether the straight joint-space segment is collision free, checked
        every ``step`` rad of the largest joint motion."""
        n = max(2, int(np.ceil(np.max(np.abs(np.asarray(q_to) - q_from)) / step)) + 1)
        for s in np.linspace(0, 1, n):
            if self.min_distance((1 - s) * np.asarray(q_from) + s * np.asarray(q_to),
                                 q_hand, 0.02) < clearance:
                return False
        return True


def wrist_joints(plant, hand, hand_spec) -> tuple[str, ...]:
    """The hand's joints that every fingertip hangs from (base to palm order): the
    Shadow hand's WRJ2, WRJ1; none for the Barrett hand."""
    by_child = {}
    for index in plant.GetJointIndices(hand):
        joint = plant.get_joint(index)
        by_child[joint.child_body().index()] = joint
    common = None
    for tip in hand_spec.fingertip_frames:
        body = plant.GetFrameByName(tip, hand).body()
        path = []
        while body.index() in by_child:
            joint = by_child[body.index()]
            if joint.num_positions() > 0:
                path.append(joint.name())
            body = joint.parent_body()
        path.reverse()
        common = path if common is None else list(
            a for a, _ in itertools.takewhile(lambda ab: ab[0] == ab[1],
                                              zip(common, path, strict=False)))
    return tuple(common or ())


def _identity():
    from pydrake.math import RotationMatrix

    return RotationMatrix()
