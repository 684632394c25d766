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
"""

from __future__ import annotations

import dataclasses as dc
import time

import numpy as np
from pydrake.math import RigidTransform
from pydrake.multibody.inverse_kinematics import InverseKinematics
from pydrake.multibody.plant import AddMultibodyPlant, MultibodyPlantConfig
from pydrake.solvers import Solve
from pydrake.systems.framework import DiagramBuilder

from handle_drake.arm.model import ARM_INSTANCE, AddArm, get_arm_spec
from handle_drake.hands import AddHand, get_hand_spec

__all__ = ["ArmReach", "IkResult"]


@dc.dataclass
class IkResult:
    q: np.ndarray | None  # arm joints (rad), None when not found
    seconds: float
    position_error: float = float("nan")  # m
    angle_error: float = float("nan")  # rad
    message: str = ""

    @property
    def ok(self) -> bool:
        return self.q is not None


class ArmReach:
    """IK for the scenario's ``!Arm`` (see module doc)."""

    def __init__(self, scenario, ignore: tuple[str, ...] = ()):
        from handle_drake.scene.config import scene_objects
        from handle_drake.scene.plant import AddSortingBox, initial_pose, spec_of

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
            from handle_drake.objects import AddTable

            AddTable(plant, top_height=scenario.table.top_height,
                     size=(scenario.table.size_x, scenario.table.size_y))
        if scenario.sorting_box is not None:
            AddSortingBox(plant, scenario)
        from handle_drake.objects import AddObject

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

    def hand_pose(self, q_arm, q_hand=None) -> RigidTransform:
        q_hand = np.zeros(len(self._hand_q)) if q_hand is None else q_hand
        self.plant.SetPositions(self.plant_context, self.positions(q_arm, q_hand))
        return self.base_frame.CalcPoseInWorld(self.plant_context)

    def solve(self, X_WB: RigidTransform, q_seed, q_hand, clearance: float = 0.003,
              position_tolerance: float = 0.002, angle_tolerance: float = 0.02,
              collision: bool = True) -> IkResult:
        """Arm joints putting the hand base at ``X_WB`` (see the module doc).

        Two stages: the kinematic problem alone (fast; when it has no solution
        from this seed, neither has the full one), then, seeded by its answer,
        with the minimum-distance constraint."""
        start = time.perf_counter()
        q_hand = np.asarray(q_hand, dtype=float)
        seed = self.positions(q_seed, q_hand)
        result, q = self._solve(X_WB, seed, q_hand, None, position_tolerance, angle_tolerance)
        if result.is_success() and collision:
            seed = result.GetSolution(q)
            if self.min_distance(seed[self._arm_q], q_hand, 0.03) < clearance:
                result, q = self._solve(X_WB, seed, q_hand, clearance, position_tolerance,
                                        angle_tolerance)
        seconds = time.perf_counter() - start
        if not result.is_success():
            return IkResult(None, seconds, message=f"IK failed ({result.get_solver_id().name()})")
        q_arm = result.GetSolution(q)[self._arm_q]
        X = self.hand_pose(q_arm, q_hand)
        return IkResult(q_arm, seconds, float(np.linalg.norm(X.translation() - X_WB.translation())),
                        float(X.rotation().InvertAndCompose(X_WB.rotation()).ToAngleAxis()
                              .angle()))

    def _solve(self, X_WB, seed, q_hand, clearance, position_tolerance, angle_tolerance):
        from pydrake.solvers import SnoptSolver

        plant = self.plant
        ik = InverseKinematics(plant, self.plant_context, with_joint_limits=True)
        q = ik.q()
        prog = ik.get_mutable_prog()
        p = X_WB.translation()
        ik.AddPositionConstraint(self.base_frame, np.zeros(3), plant.world_frame(),
                                 p - position_tolerance, p + position_tolerance)
        ik.AddOrientationConstraint(plant.world_frame(), X_WB.rotation(), self.base_frame,
                                    _identity(), angle_tolerance)
        prog.AddBoundingBoxConstraint(q_hand, q_hand, q[self._hand_q])
        prog.AddQuadraticErrorCost(np.eye(len(self._arm_q)), seed[self._arm_q], q[self._arm_q])
        if clearance is not None:
            ik.AddMinimumDistanceLowerBoundConstraint(clearance, 0.03)
        # Bounded effort: a pose out of reach fails in a fraction of a second.
        prog.SetSolverOption(SnoptSolver.id(), "Major iterations limit", 100)
        return Solve(prog, seed), q

    def solve_from_seeds(self, X_WB: RigidTransform, seeds, q_hand, tries: int = 4,
                         rng=None, **options) -> IkResult:
        """:meth:`solve` from each seed, then from ``tries`` random configurations
        within the limits; the first success (total time in ``seconds``)."""
        rng = np.random.default_rng(0) if rng is None else rng
        seeds = [np.asarray(s, dtype=float) for s in seeds]
        seeds += [rng.uniform(self.spec.lower, self.spec.upper) for _ in range(tries)]
        total = 0.0
        result = IkResult(None, 0.0, message="no seed")
        for seed in seeds:
            result = self.solve(X_WB, seed, q_hand, **options)
            total += result.seconds
            if result.ok:
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


def _identity():
    from pydrake.math import RotationMatrix

    return RotationMatrix()
