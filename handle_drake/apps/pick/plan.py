"""Plan a pick and place: the grasp planner's hand poses, arm configurations that
reach them, collision-checked joint paths, and the release over the object's hole.

:func:`plan_pick` tries the grasp classes of ``CLASS_ORDER[kind]`` in turn. For
each, the floating-wrist planner (:func:`handle_drake.grasp.planning.plan_grasp`,
reaching from the arm's base towards the object) gives the pre-grasp, grasp and
lift poses of the hand base; :class:`handle_drake.apps.pick.reach.ArmReach` finds arm
joints for each (limits, 3 mm clearance; each IK seeded by the previous
configuration). The release pose keeps the grasp (``X_OB``, object to hand
base, as planned) and puts the object ``DROP_HEIGHT`` above its hole, turned to
the hole's orientation (a cuboid's width along the box's x, either way round;
a sphere at its own yaw or a quarter or half turn from it, whichever the arm
reaches); a carry pose ``CARRY_HEIGHT`` higher comes before it. Between
consecutive configurations the straight joint-space segment must be collision
free (checked every 0.02 rad with the hand's posture of that phase); if one is
not, Drake's ``KinematicTrajectoryOptimization`` looks for a collision-free
path between the two (:func:`free_path`). The first class whose whole chain
exists is the plan; otherwise :class:`PickPlanningError` lists each class's
reason.
"""

from __future__ import annotations

import dataclasses as dc
import functools
import math
import time
from pathlib import Path

import numpy as np
from pydrake.math import RigidTransform, RollPitchYaw

from handle_drake.base.hands import actuated_to_joint_positions, get_hand_spec
from handle_drake.devices.arm.config import Arm
from handle_drake.geometry.objects import ObjectSpec, resting_height
from handle_drake.grasp.database import GraspDatabase, build_database
from handle_drake.grasp.planning import grasp_key, plan_grasp
from handle_drake.scene.config import box_pose, hole_centres

__all__ = ["PickPlan", "PickPlanningError", "plan_pick", "CLASS_ORDER", "GRASP_BUDGET",
           "GRASP_TOTAL_BUDGET", "GRASP_DB", "SIZE_TOLERANCE", "catalogue_size",
           "default_grasp_database", "grasp_db_requests", "build_grasp_database",
           "free_path", "replan_release"]

#: The pick application's grasp database (``handle-drake pick SCENARIO
#: --build-grasp-db`` writes it): the planner's answers for the sorting box's objects
#: (:mod:`handle_drake.grasp.database`).
GRASP_DB = Path(__file__).resolve().parent / "data" / "grasp_database.json"
#: A perceived object whose size is this close to a catalogue object's of its kind (the
#: sorting box's holes name the catalogue) is that object: it is planned with the
#: catalogue size, resting on the table, so the stored grasps apply.
SIZE_TOLERANCE = 0.005  # m

#: Grasp classes tried for each kind, in order: the power-ish grasps that held the object
#: through lift and carry in bench_pick first (lateral tripod let a cuboid swing 32 deg).
CLASS_ORDER = {
    "sphere": ("tripod", "parallel_extension", "palmar_pinch", "lateral_tripod",
               "writing_tripod", "tip_pinch", "adduction_grip", "lateral"),
    "cuboid": ("parallel_extension", "tripod", "palmar_pinch", "lateral_tripod",
               "writing_tripod", "tip_pinch", "adduction_grip", "lateral"),
}
#: Seconds the grasp planner's hand-IK search may take per class (``plan_grasp``'s
#: ``time_budget``): a class that has not found a grasp by then is reported as timed out
#: and the next is tried. The classes taken in bench_pick (tripod on a sphere, parallel
#: extension on a cuboid) took 0.9-7 s cold at load 9 on 2 cores; the failing ones up to
#: 45 s each (docs/results/pick.md).
GRASP_BUDGET = 10.0  # s
#: Seconds all classes' grasp searches together may take (each gets the least of
#: ``GRASP_BUDGET`` and what is left); the classes after it are reported as not tried.
GRASP_TOTAL_BUDGET = 30.0  # s
DROP_HEIGHT = 0.03  # m, object bottom above the lid's top when let go
CARRY_HEIGHT = 0.12  # m, above the release pose


class PickPlanningError(ValueError):
    """No grasp class gives a reachable, collision-free pick; the message says why."""


@functools.lru_cache(maxsize=1)
def default_grasp_database() -> GraspDatabase:
    """The shipped database (:data:`GRASP_DB`), read once per process."""
    return GraspDatabase.load(GRASP_DB)


def catalogue_size(scenario, kind: str, size: float) -> float:
    """The size of the sorting box's ``kind`` object if ``size`` is within
    ``SIZE_TOLERANCE`` of it, else ``size``."""
    box = scenario.sorting_box
    sizes = [h.size for h in (box.holes if box is not None else []) if h.kind == kind
             and h.size]
    near = min(sizes, key=lambda s: abs(s - size), default=None)
    return float(near) if near is not None and abs(near - size) <= SIZE_TOLERANCE \
        else float(size)


def _as_catalogue(scenario, kind, size, X_WO):
    """``(size, X_WO)``: the catalogue object's size (:func:`catalogue_size`) and, if
    it is not ``size``, the pose of that object resting on the table where it was seen."""
    known = catalogue_size(scenario, kind, size)
    if known == size:
        return size, X_WO
    z = scenario.table.top_height + resting_height(ObjectSpec(kind=kind, size=known))
    return known, RigidTransform(X_WO.rotation(), [*X_WO.translation()[:2], z])


def grasp_db_requests(scenario) -> list:
    """``(class, (kind, size), height)`` of every class of ``CLASS_ORDER`` on each
    pickable object the scenario's sorting box has a hole for, resting on the table."""
    out = []
    for hole in scenario.sorting_box.holes if scenario.sorting_box is not None else []:
        if hole.kind not in CLASS_ORDER or not hole.size:
            continue
        spec = ObjectSpec(kind=hole.kind, size=float(hole.size))
        out += [(cls, (hole.kind, float(hole.size)), resting_height(spec))
                for cls in CLASS_ORDER[hole.kind]]
    return out


def build_grasp_database(scenario, path=GRASP_DB, rebuild: bool = False,
                         time_budget: float | None = None, log=print) -> GraspDatabase:
    """(Re)computes the database at ``path`` for ``scenario``'s catalogue objects
    (:func:`grasp_db_requests`); keeps its current entries unless ``rebuild``."""
    path = Path(path)
    database = GraspDatabase()
    if path.exists() and not rebuild:
        old = GraspDatabase.load(path)
        database = GraspDatabase(old.entries)
    build_database(grasp_db_requests(scenario), database,
                   coupling_ratio=scenario.hand.coupling_ratio or 1.0,
                   time_budget=time_budget, rebuild=rebuild, log=log)
    database.save(path, meta={"built_by": "handle-drake pick SCENARIO --build-grasp-db",
                              "table_height": scenario.table.top_height})
    return database


@dc.dataclass
class Waypoint:
    label: str
    q: np.ndarray  # arm joints (rad)
    hand: np.ndarray  # hand command (actuated joints, rad) held from here on
    path: list | None = None  # intermediate arm configurations from the previous waypoint


@dc.dataclass
class PickPlan:
    target: str
    kind: str
    grasp_class: str
    grasp: object  # the GraspPlan
    waypoints: list[Waypoint]
    X_WO: RigidTransform  # the pose planned on (perceived or true)
    X_WO_release: RigidTransform
    seconds: dict  # grasp planning, IK and path times (s)
    attempts: dict  # class -> reason it was not taken
    grasp_stored: bool = False  # the grasp came from the grasp database
    # Hand joints the arm's IK set per waypoint (an arm with fewer than six joints:
    # the wrist, reach.ArmReach); the hand's commands carry them.
    wrist_from_ik: tuple[str, ...] = ()

    def summary(self) -> str:
        t = self.seconds
        return (f"{self.target} ({self.kind}): {self.grasp_class}; planning "
                f"{t['grasp']:.2f} s grasp + {t['ik']:.2f} s IK + {t['path']:.2f} s paths")


def _yaw(R) -> float:
    m = R.matrix()
    return math.atan2(m[1, 0], m[0, 0])


def _release_poses(scenario, kind, spec, X_WO, X_OB):
    """Candidate (X_WO_release, X_WB_release), nearest turn first."""

    centre = hole_centres(scenario)[kind]
    z = centre[2] + resting_height(spec) + DROP_HEIGHT
    yaw0 = _yaw(X_WO.rotation())
    if kind == "cuboid":  # its square hole takes it at every quarter turn
        box_yaw = _yaw(box_pose(scenario).rotation())
        yaws = [box_yaw + k * math.pi / 2 for k in range(4)]
    else:
        yaws = [yaw0 + k * math.pi / 2 for k in (0, 1, -1, 2)]
    yaws.sort(key=lambda y: abs((y - yaw0 + math.pi) % (2 * math.pi) - math.pi))
    if kind == "sphere" and isinstance(scenario.hand.mount, Arm):
        # Last: the turn that keeps the hand on the same side of the sphere as seen from
        # the arm's base, which an arm with fewer than six joints may need.
        base = scenario.hand.mount.X_WB.GetDeterministicValue().translation()
        p_WO = X_WO.translation()
        yaws.append(yaw0 + math.atan2(centre[1] - base[1], centre[0] - base[0])
                    - math.atan2(p_WO[1] - base[1], p_WO[0] - base[0]))
    out = []
    for yaw in yaws:
        X = RigidTransform(RollPitchYaw(0, 0, yaw), [centre[0], centre[1], z])
        out.append((X, X @ X_OB))
    return out


def _raised(X: RigidTransform, dz: float) -> RigidTransform:
    return RigidTransform(X.rotation(), X.translation() + [0, 0, dz])


def free_path(reach, q_from, q_to, q_hand, clearance: float = 0.002):
    """A collision-free joint path from ``q_from`` to ``q_to`` (list of arm
    configurations, ends excluded) by Drake's ``KinematicTrajectoryOptimization``
    (B-spline, minimum duration + length, joint position and velocity limits,
    the minimum-distance constraint at sample points; 10 control points and 20
    samples, then 14 and 28), or None. The result is checked densely
    (:meth:`ArmReach.path_is_free` between consecutive samples)."""
    for num_control_points, samples in ((10, 20), (14, 28)):
        path = _kto_path(reach, q_from, q_to, q_hand, num_control_points, samples, clearance)
        if path is not None:
            return path
    return None


def _kto_path(reach, q_from, q_to, q_hand, num_control_points, samples, clearance):
    from pydrake.multibody.inverse_kinematics import MinimumDistanceLowerBoundConstraint
    from pydrake.planning import KinematicTrajectoryOptimization
    from pydrake.solvers import SnoptSolver, Solve

    plant = reach.plant
    n = plant.num_positions()
    a, b = reach.positions(q_from, q_hand), reach.positions(q_to, q_hand)
    trajopt = KinematicTrajectoryOptimization(n, num_control_points)
    prog = trajopt.get_mutable_prog()
    trajopt.AddDurationCost(1.0)
    trajopt.AddPathLengthCost(1.0)
    lower, upper = plant.GetPositionLowerLimits(), plant.GetPositionUpperLimits()
    lower, upper = np.where(np.isfinite(lower), lower, -10), np.where(np.isfinite(upper), upper, 10)
    lower[reach._hand_q] = upper[reach._hand_q] = q_hand
    trajopt.AddPositionBounds(lower, upper)
    velocity = np.full(n, 10.0)
    velocity[reach._arm_q] = reach.spec.velocity
    trajopt.AddVelocityBounds(-velocity, velocity)
    trajopt.AddDurationConstraint(0.2, 20.0)
    trajopt.AddPathPositionConstraint(a, a, 0)
    trajopt.AddPathPositionConstraint(b, b, 1)
    trajopt.AddPathVelocityConstraint(np.zeros(n), np.zeros(n), 0)
    trajopt.AddPathVelocityConstraint(np.zeros(n), np.zeros(n), 1)
    constraint = MinimumDistanceLowerBoundConstraint(plant, clearance, reach.plant_context, None,
                                                     0.02)
    for s in np.linspace(0, 1, samples)[1:-1]:
        trajopt.AddPathPositionConstraint(constraint, s)
    # Initial guess: the straight segment.
    guess = np.linspace(a, b, num_control_points).T
    from pydrake.trajectories import BsplineTrajectory

    trajopt.SetInitialGuess(BsplineTrajectory(trajopt.basis(), list(guess.T[:, :, None])))
    prog.SetSolverOption(SnoptSolver.id(), "Major iterations limit", 300)
    result = Solve(prog)
    if not result.is_success():
        return None
    trajectory = trajopt.ReconstructTrajectory(result)
    times = np.linspace(trajectory.start_time(), trajectory.end_time(), samples)
    path = [trajectory.value(t).ravel()[reach._arm_q] for t in times[1:-1]]
    points = [np.asarray(q_from)] + path + [np.asarray(q_to)]
    segments = zip(points, points[1:], strict=False)
    if not all(reach.path_is_free(p, q, q_hand, clearance=0.0) for p, q in segments):
        return None
    return path


def plan_pick(scenario, reach, target: str, kind: str, size: float, X_WO: RigidTransform,
              q_start, classes=None, grasp_budget: float | None = GRASP_BUDGET,
              total_budget: float | None = GRASP_TOTAL_BUDGET,
              grasp_db: GraspDatabase | None = None) -> PickPlan:
    """Plans picking ``target`` (a ``kind`` of ``size`` at ``X_WO``) into its hole
    (see the module doc). ``reach`` is an :class:`~handle_drake.apps.pick.reach.ArmReach`
    of the scenario ignoring ``target``; ``q_start`` the arm's joints now;
    ``grasp_budget`` the seconds each class's grasp search may take, ``total_budget``
    all of them together (None: unbounded).

    The grasps come from ``grasp_db`` (default: the shipped :data:`GRASP_DB`; an
    empty ``GraspDatabase()`` for none): an object within ``SIZE_TOLERANCE`` of a
    catalogue size is planned as that catalogue object resting on the table, so
    every class's grasp is a stored one and only the arm's IK and paths are
    computed. A kind or size the database lacks is searched (within the budgets) and
    the answer reused for the rest of the process (``plan_grasp``'s ``cache``)."""

    if kind not in CLASS_ORDER:
        raise PickPlanningError(f"{target}: no grasp for a {kind} (pick takes "
                                f"{sorted(CLASS_ORDER)})")
    ratio = scenario.hand.coupling_ratio or 1.0
    hand = get_hand_spec(scenario.hand.kind)
    base = scenario.hand.mount.X_WB.GetDeterministicValue().translation()
    grasp_db = default_grasp_database() if grasp_db is None else grasp_db
    size, X_WO = _as_catalogue(scenario, kind, size, X_WO)
    spec = ObjectSpec(kind=kind, size=size)
    q_start = np.asarray(q_start, dtype=float)
    attempts, seconds = {}, {"grasp": 0.0, "ik": 0.0, "path": 0.0}
    for cls in classes or CLASS_ORDER[kind]:
        budget = grasp_budget
        if total_budget is not None:
            left = total_budget - seconds["grasp"]
            if left <= 0:
                attempts[cls] = f"not tried: the grasp planning budget ({total_budget} s) is spent"
                continue
            budget = left if budget is None else min(budget, left)
        start = time.perf_counter()
        stored = grasp_key(cls, spec, X_WO.translation()[2] - scenario.table.top_height,
                           ratio) in grasp_db
        try:
            grasp = plan_grasp(cls, spec, X_WO, table_height=scenario.table.top_height,
                               reach_direction=X_WO.translation()[:2] - base[:2],
                               coupling_ratio=ratio, time_budget=budget,
                               database=grasp_db)
        except ValueError as error:
            attempts[cls] = f"no grasp plan: {str(error)[:100]}"
            seconds["grasp"] += time.perf_counter() - start
            continue
        seconds["grasp"] += time.perf_counter() - start
        q_open = actuated_to_joint_positions(hand, grasp.preshape_command, ratio)
        q_closed = actuated_to_joint_positions(hand, grasp.close_command, ratio)
        X_OB = X_WO.inverse() @ grasp.X_WB
        chain = [("pregrasp", grasp.X_WB_pregrasp, q_open, grasp.preshape_command),
                 ("grasp", grasp.X_WB, q_open, grasp.preshape_command),
                 ("close", None, q_closed, grasp.close_command),
                 ("lift", grasp.lifted(), q_closed, grasp.close_command)]
        waypoints = [Waypoint("start", q_start, grasp.preshape_command)]
        symmetry = (kind, X_OB.inverse().translation())  # used by arms with < 6 joints
        reason = _solve_chain(reach, chain, waypoints, seconds, symmetry)
        X_release = None
        if not reason:
            reason = "no IK for the carry and release poses at any turn over the hole"
            for X_WO_rel, X_WB_rel in _release_poses(scenario, kind, spec, X_WO, X_OB):
                tail = [("carry", _raised(X_WB_rel, CARRY_HEIGHT), q_closed, grasp.close_command),
                        ("release", X_WB_rel, q_closed, grasp.close_command),
                        ("open", None, q_open, grasp.preshape_command)]
                trial = list(waypoints)
                if not _solve_chain(reach, tail, trial, seconds, symmetry):
                    waypoints, X_release, reason = trial, X_WO_rel, ""
                    break
        if not reason:
            reason = _connect(reach, waypoints, seconds)
        if reason:
            attempts[cls] = reason
            continue
        return PickPlan(target, kind, cls, grasp, waypoints, X_WO, X_release, seconds, attempts,
                        stored, tuple(getattr(reach, "free_hand_joints", ())))
    raise PickPlanningError(f"{target} ({kind}): no reachable pick; " + "; ".join(
        f"{c}: {r}" for c, r in attempts.items()))


def replan_release(scenario, reach, plan: PickPlan, X_OB_measured: RigidTransform):
    """The carry, release and open waypoints again, for the object held at
    ``X_OB_measured`` (object to hand base, as measured after the lift) instead of the
    planned grasp: ``(waypoints, X_WO_release)`` with the plan's waypoints up to the
    lift unchanged, or None when no turn over the hole is reachable and collision
    free with it (the caller keeps the plan)."""
    ratio = scenario.hand.coupling_ratio or 1.0
    hand = get_hand_spec(scenario.hand.kind)
    grasp = plan.grasp
    q_open = actuated_to_joint_positions(hand, grasp.preshape_command, ratio)
    q_closed = actuated_to_joint_positions(hand, grasp.close_command, ratio)
    labels = [w.label for w in plan.waypoints]
    head = [dc.replace(w) for w in plan.waypoints[:labels.index("lift") + 1]]
    spec = grasp.object_spec
    X_WO_lift = reach.hand_pose(head[-1].q) @ X_OB_measured.inverse()
    if getattr(reach, "free_hand_joints", ()):
        # The IK moved the wrist at the lift: the object as held in the palm there, given
        # to the release's IK with the plan's wrist (which it turns into a palm pose).
        q_lift = actuated_to_joint_positions(hand, head[-1].hand, ratio)
        X_PO = reach.palm_in_base(q_lift).inverse() @ X_OB_measured.inverse()
        X_OB_measured = (reach.palm_in_base(q_closed) @ X_PO).inverse()
    seconds = {"ik": 0.0, "path": 0.0}
    for X_WO_rel, X_WB_rel in _release_poses(scenario, plan.kind, spec, X_WO_lift,
                                              X_OB_measured):
        tail = [("carry", _raised(X_WB_rel, CARRY_HEIGHT), q_closed, grasp.close_command),
                ("release", X_WB_rel, q_closed, grasp.close_command),
                ("open", None, q_open, grasp.preshape_command)]
        trial = list(head)
        if _solve_chain(reach, tail, trial, seconds,
                        (plan.kind, X_OB_measured.inverse().translation())):
            continue
        moved = trial[len(head) - 1:]
        if not _connect(reach, moved, seconds):
            return trial, X_WO_rel
    return None


def _solve_chain(reach, chain, waypoints, seconds, symmetry=None) -> str:
    """IK for each ``(label, X_WB, q_hand, command)`` of ``chain``, appended to
    ``waypoints``; ``symmetry``: the grasped object's (:meth:`ArmReach.solve`)."""
    options = {} if symmetry is None else {"symmetry": symmetry}
    for label, X, q_hand, command in chain:
        previous = waypoints[-1]
        if X is None:  # the hand changes posture where the arm stands
            waypoints.append(Waypoint(label, previous.q,
                                      _with_wrist(reach, command, previous.hand)))
            continue
        result = reach.solve_from_seeds(X, [previous.q, waypoints[0].q], q_hand, tries=2,
                                        **options)
        seconds["ik"] += result.seconds
        if not result.ok:
            return f"no IK for the {label} pose"
        if result.q_hand is not None:  # an arm with < 6 joints moved the hand's wrist
            hand_names = reach.hand_spec.joint_names
            command = _with_wrist(reach, command, None, {
                n: result.q_hand[hand_names.index(n)] for n in reach.free_hand_joints})
        waypoints.append(Waypoint(label, result.q, command))
    return ""


def _with_wrist(reach, command, source=None, values=None):
    """``command`` with the IK's wrist joints (``reach.free_hand_joints``, arms with
    fewer than six joints) from ``values`` (name -> rad) or the command ``source``."""
    free = getattr(reach, "free_hand_joints", ())
    if not free or (source is None and values is None):
        return command
    names = list(reach.hand_spec.actuated_joint_names)
    out = np.array(command, dtype=float)
    for name in free:
        i = names.index(name)
        out[i] = values[name] if values is not None else source[i]
    return out


def _connect(reach, waypoints, seconds) -> str:

    start = time.perf_counter()
    hand = get_hand_spec(reach.hand_spec.name)
    try:
        for a, b in zip(waypoints, waypoints[1:], strict=False):
            if np.allclose(a.q, b.q):
                continue
            # The posture held while the arm moves from a to b is a's command.
            q_hand = actuated_to_joint_positions(hand, a.hand, reach.coupling_ratio)
            if reach.path_is_free(a.q, b.q, q_hand):
                continue
            path = free_path(reach, a.q, b.q, q_hand)
            if path is None:
                return f"no collision-free path from {a.label} to {b.label}"
            b.path = path
        return ""
    finally:
        seconds["path"] += time.perf_counter() - start
