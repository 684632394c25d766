"""Plan a pick and place: the grasp planner's hand poses, arm configurations that
reach them, collision-checked joint paths, and the release over the object's hole.

:func:`plan_pick` tries the grasp classes of ``CLASS_ORDER[kind]`` in turn, first each
from the grasp database (:data:`GRASP_DB`: the stored grasp, or the nearest stored one
adapted to the perceived size by one seeded IK solve and the planner's acceptance test,
:func:`handle_drake.grasp.planning.adapt_grasp`), then, for the classes the database
cannot serve, by a search within ``GRASP_BUDGET`` / ``GRASP_TOTAL_BUDGET``. For each,
the floating-wrist planner (:func:`handle_drake.grasp.planning.plan_grasp`, reaching
from the arm's base towards the object) gives the pre-grasp, grasp and lift poses of the
hand base; :class:`handle_drake.apps.pick.reach.ArmReach` finds arm joints for each
(limits, 3 mm clearance; each IK seeded by the previous configuration). The release pose
keeps the grasp (``X_OB``, object to hand base, as planned) and puts the object's bottom
``DROP_HEIGHT`` above its hole (first any ``RELEASE_INSERTS`` of its kind), turned
to the hole's orientation (a cuboid's width along the box's x, either way round; a
sphere at its own yaw or a quarter or half turn from
it, whichever the arm reaches); a carry pose ``CARRY_HEIGHT`` higher comes before it.
The kinds beyond the planner's sphere and upright cuboid (a cylinder, a rotated cuboid, a
mug, a wine glass, a star prism, a user's mesh) are planned through an upright cuboid proxy
(:mod:`handle_drake.apps.pick.kinds`; their stored grasps in :data:`GRASP_DB_KINDS`) and
released upright at a yaw their hole takes (:func:`handle_drake.scene.config.release_yaws`).
Between consecutive configurations the straight joint-space segment must be collision
free (checked every 0.02 rad with the hand's posture of that phase); if one is not, a
via point with the hand raised, then Drake's ``KinematicTrajectoryOptimization``, looks
for a collision-free path between the two (:func:`free_path`). The first class whose
whole chain exists is the plan; otherwise :class:`PickPlanningError` lists each class's
reason. The arm's work is bounded by a count, not the clock: at most
``PLAN_IK_BUDGET`` IK solves per plan (a path search counts ``PATH_SEARCH_COST``),
each solve bounded by its iterations (:class:`~handle_drake.apps.pick.reach.ArmReach`);
past it the planner stops and says so.
"""

from __future__ import annotations

import dataclasses as dc
import functools
import math
import time
from pathlib import Path

import numpy as np
from pydrake.math import RigidTransform, RollPitchYaw, RotationMatrix

from handle_drake.apps.pick.kinds import PROXY_KINDS, grasp_proxy, proxied_plan, proxy_height
from handle_drake.apps.pick.reach import BUDGET_SPENT
from handle_drake.base.hands import actuated_to_joint_positions, get_hand_spec
from handle_drake.devices.arm.config import Arm
from handle_drake.devices.arm.model import get_arm_spec
from handle_drake.geometry.objects import ObjectSpec, resting_height
from handle_drake.grasp.database import GraspDatabase, build_database
from handle_drake.grasp.planning import grasp_key, plan_grasp
from handle_drake.scene.config import box_pose, hole_centres, hole_spec, release_yaws

__all__ = ["PickPlan", "PickPlanningError", "plan_pick", "CLASS_ORDER", "GRASP_BUDGET",
           "GRASP_TOTAL_BUDGET", "GRASP_DB", "SIZE_TOLERANCE", "catalogue_size",
           "default_grasp_database", "grasp_db_requests", "build_grasp_database",
           "free_path", "replan_release", "GRASP_SOURCES", "PLAN_IK_BUDGET", "PATH_SEARCH_COST",
           "RELEASE_INSERTS"]

#: The pick application's grasp database (``handle-drake pick SCENARIO
#: --build-grasp-db`` writes it): the planner's answers for the sorting box's objects
#: (:mod:`handle_drake.grasp.database`).
GRASP_DB = Path(__file__).resolve().parent / "data" / "grasp_database.json"
#: A perceived object whose size is this close to a catalogue object's of its kind (the
#: sorting box's holes name the catalogue) is that object: it is planned with the
#: catalogue size, resting on the table, so the stored grasps apply as they are. Any
#: other size is planned as seen, with the nearest stored grasp of each class adapted
#: to it (:func:`handle_drake.grasp.planning.adapt_grasp`: one seeded IK solve and the
#: planner's acceptance test, 0.1-0.8 s), not searched: no step in planning time here.
SIZE_TOLERANCE = 0.005  # m

#: Grasp classes tried for each kind, in order: the power-ish grasps that held the object
#: through lift and carry in bench_pick first (lateral tripod let a cuboid swing 32 deg).
CLASS_ORDER = {
    "sphere": ("tripod", "parallel_extension", "palmar_pinch", "lateral_tripod",
               "writing_tripod", "tip_pinch", "adduction_grip", "lateral"),
    "cuboid": ("parallel_extension", "tripod", "palmar_pinch", "lateral_tripod",
               "writing_tripod", "tip_pinch", "adduction_grip", "lateral"),
    # The other kinds, grasped through their cuboid proxies (apps/pick/kinds.py): the
    # grasps that close across a 5-6 cm object (Table 1's size ranges) in the
    # cuboid's order.
    **dict.fromkeys(PROXY_KINDS, ("parallel_extension", "tripod", "palmar_pinch")),
}
#: Seconds each class's grasp search may take (``plan_grasp``'s ``time_budget``). Every
#: class is first served from the database (stored, or adapted to the size: 0.1-0.8 s on
#: a quiet machine, bounded by its solves' iterations, ``ADAPT_ITERATIONS``, not by the
#: clock, so the grasp taken does not depend on the load); only the classes it cannot
#: serve (a kind it lacks) are then searched, within these budgets (the search checks
#: the deadline before each IK solve: one solve can overrun it). A class with no grasp
#: by then is reported as timed out and the next is tried. (Cold searches of the 6 cm
#: objects took 0.3-45 s: they belong in ``--build-grasp-db``, not in a pick.)
GRASP_BUDGET = 2.0  # s
#: Seconds all classes' grasps together may take (each gets the least of
#: ``GRASP_BUDGET`` and what is left); the classes after it are reported as not tried.
GRASP_TOTAL_BUDGET = 2.0  # s
#: Where a plan's grasp came from (``PickPlan.grasp_source``).
GRASP_SOURCES = ("stored", "adapted", "searched")
#: Turns (rad) about the vertical of a cuboid's grasp tried in turn when the arm reaches
#: none at the object's own yaw: the squeeze turns the cuboid to the fingers. (On seeds 6
#: and 8 of 0-19 the arm reached the parallel extension's pre-grasp within 0.1 rad but
#: not 0.02; turned -5 deg it reaches it. Development seeds 20-59, the 18 scenes whose
#: nearest object is a cuboid, parallel extension's pre-grasp and grasp reached: 15 at
#: 0 deg, 16 with +-5, 17 with +-10, 18 with +-20.)
GRASP_TURNS = {"cuboid": tuple(np.radians([0.0, -5.0, 5.0, -10.0, 10.0, -20.0, 20.0]))}
#: The proxied kinds' grasps turn as the cuboid's (apps/pick/kinds.py: each is a cuboid
#: to the planner; the release turns the object back to a yaw its hole takes). Round ones
#: further: a cylinder's, mug's and glass's grasp holds at any turn about their axis.
GRASP_TURNS.update(dict.fromkeys(PROXY_KINDS, GRASP_TURNS["cuboid"]))
GRASP_TURNS.update(dict.fromkeys(("cylinder", "wine_glass"), tuple(np.radians(
    [0.0, -5.0, 5.0, -10.0, 10.0, -20.0, 20.0, -45.0, 45.0, -90.0, 90.0]))))
#: The classes whose grasp is turned (``GRASP_TURNS``): the ones that lift a cuboid; each
#: turn costs the arm's IK of its poses (a held-out cuboid trying every turn of all eight
#: classes planned for 77 s at load 14).
TURNED_CLASSES = ("parallel_extension", "tripod")
#: IK solves (:meth:`ArmReach.solve` calls, each at most two SNOPT solves of 100 major
#: iterations; a path search counts ``PATH_SEARCH_COST``) one :func:`plan_pick` may
#: make over every class, turn and release pose: past it nothing more is tried. Each
#: pose is solved from the previous waypoint and from the start only (no random
#: seeds: on development seeds 0-59 a random seed found none of 104 poses the two
#: missed). A plan takes 5 (pre-grasp, grasp, lift, carry, release), one more per
#: turn or release yaw the arm does not reach.
PLAN_IK_BUDGET = 40
#: What one path search (``KinematicTrajectoryOptimization``, :func:`free_path`)
#: counts against ``PLAN_IK_BUDGET``, in IK solves.
PATH_SEARCH_COST = 20
#: Heights (m) the hand is raised to for a via point between two configurations
#: whose straight joint segment collides (:func:`free_path`).
VIA_RISES = (0.10, 0.20)
#: Where the grasp database of the kinds planned through a cuboid proxy is kept (its
#: entries are read with :data:`GRASP_DB`'s: :func:`default_grasp_database`).
GRASP_DB_KINDS = GRASP_DB.with_name("grasp_database_kinds.json")
DROP_HEIGHT = 0.03  # m, object bottom above the lid's top when let go
#: Heights (m, negative: below the lid's top) of a kind's bottom at the release tried
#: before ``DROP_HEIGHT``, each at every turn over the hole. A cuboid 1 cm above its hole:
#: the opening fingers tip it as it slides out (tilted 8 deg in the hand). Development
#: seeds 2, 4, 6, 8, 9, 10, 13 (perceived, 1 and 0.5 ms): let go 3 cm above the lid it came
#: down to the lid 8.7-25.3 deg tilted (8 of 14 over 15), 13/14 in the box (10 at 0.5 ms
#: wedged); 1 cm above, 6.5-10.1 deg in 12 of 14 (24 twice), 14/14 in the box. A 6 cm cube
#: spans its 84 mm hole (60 (cos t + sin t) = 84) and can wedge across it from 36.9 deg.
#: 5 mm measured the same (2, 4, 6); 1 cm leaves the IK's 4 mm and the tilted cube's lower corner
#: room. Tried: the bottom 2 cm, else 1 cm, into the hole (development seed 6 at 0.5 ms,
#: the release 14 mm off before ``execute.RELEASE_DWELL``: it hit the rim on the way down
#: and wedged). The arm's IK checks the hand at the planned closing posture, not the
#: reactive close's, and not the object against the lid.
RELEASE_INSERTS: dict = {"cuboid": (0.01,)}
CARRY_HEIGHT = 0.12  # m, above the release pose


_NOT_STORED = "no grasp plan: no stored"  # a class the database could not serve


class PickPlanningError(ValueError):
    """No grasp class gives a reachable, collision-free pick; the message says why."""


@functools.lru_cache(maxsize=1)
def default_grasp_database() -> GraspDatabase:
    """The shipped database (:data:`GRASP_DB` and :data:`GRASP_DB_KINDS`'s entries),
    read once per process."""
    database = GraspDatabase.load(GRASP_DB)
    if GRASP_DB_KINDS.exists():
        kinds = GraspDatabase.load(GRASP_DB_KINDS)
        database = GraspDatabase({**kinds.entries, **database.entries}, database.version,
                                 database.path, database.stale + kinds.stale)
    return database


def _plan_grasp(grasp_class, spec, X_WO, **kwargs):
    """``plan_grasp``, through the kind's cuboid proxy for :data:`PROXY_KINDS`
    (:func:`handle_drake.apps.pick.kinds.proxied_plan`)."""
    if spec.kind in PROXY_KINDS:
        return proxied_plan(plan_grasp, grasp_class, spec, X_WO, **kwargs)
    return plan_grasp(grasp_class, spec, X_WO, **kwargs)


def _grasp_key(grasp_class, spec, height, ratio):
    """``grasp_key`` of the grasp ``_plan_grasp`` plans (a proxy's for a proxied kind)."""
    if spec.kind in PROXY_KINDS:
        return grasp_key(grasp_class, grasp_proxy(spec)[0], proxy_height(spec, height), ratio)
    return grasp_key(grasp_class, spec, height, ratio)


def _spec(scenario, kind, size):
    """The object spec of a ``kind`` of ``size`` (a user's mesh: the sorting box's)."""
    if kind == "mesh":
        holes = [h for h in scenario.sorting_box.holes if h.kind == "mesh"]
        return hole_spec(holes[0])
    return ObjectSpec(kind=kind, size=size)


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
    if known == size or kind == "mesh":
        return size, X_WO
    z = scenario.table.top_height + resting_height(ObjectSpec(kind=kind, size=known))
    return known, RigidTransform(X_WO.rotation(), [*X_WO.translation()[:2], z])


def grasp_db_requests(scenario) -> list:
    """``(class, (kind, size), height)`` of every class of ``CLASS_ORDER`` on each
    pickable object the scenario's sorting box has a hole for, resting on the table."""
    out = []
    for hole in scenario.sorting_box.holes if scenario.sorting_box is not None else []:
        if hole.kind not in CLASS_ORDER or not (hole.size or hole.kind == "mesh"):
            continue
        spec = hole_spec(hole)
        if hole.kind in PROXY_KINDS:  # the cuboid proxy's grasps (apps/pick/kinds.py)
            proxy = grasp_proxy(spec)[0]
            height = proxy_height(spec, resting_height(spec))
            out += [(cls, proxy, height) for cls in CLASS_ORDER[hole.kind]]
            continue
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
    grasp_source: str = "searched"  # one of GRASP_SOURCES
    # Per class tried, in order: (class, where its grasp came from or "failed", seconds).
    grasp_log: list = dc.field(default_factory=list)
    # Hand joints the arm's IK set per waypoint (an arm with fewer than six joints:
    # the wrist, reach.ArmReach); the hand's commands carry them.
    wrist_from_ik: tuple[str, ...] = ()
    # The arm's IK solves the plan took (ArmReach.solve calls; ``ik_budget`` bounds them).
    ik_solves: int = 0

    @property
    def grasp_stored(self) -> bool:
        """The grasp came from the grasp database as stored."""
        return self.grasp_source == "stored"

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
    yaw0 = _yaw(X_WO.rotation())
    if kind == "cuboid":  # its square hole takes it at every quarter turn
        box_yaw = _yaw(box_pose(scenario).rotation())
        yaws = [box_yaw + k * math.pi / 2 for k in range(4)]
    elif release_yaws(scenario, kind) is not None:  # its hole's yaws (a star, a mug...)
        yaws = release_yaws(scenario, kind)
    else:
        yaws = [yaw0 + k * math.pi / 2 for k in (0, 1, -1, 2)]
    yaws.sort(key=lambda y: abs((y - yaw0 + math.pi) % (2 * math.pi) - math.pi))
    mount = scenario.hand.mount
    if kind == "sphere" and isinstance(mount, Arm) and len(
            get_arm_spec(mount.kind).joint_names) < 6:
        # Last: the turn that keeps the hand on the same side of the sphere as seen from
        # the arm's base, which an arm with fewer than six joints may need.
        base = scenario.hand.mount.X_WB.GetDeterministicValue().translation()
        p_WO = X_WO.translation()
        yaws.append(yaw0 + math.atan2(centre[1] - base[1], centre[0] - base[0])
                    - math.atan2(p_WO[1] - base[1], p_WO[0] - base[0]))
    out = []
    for drop in (*RELEASE_INSERTS.get(kind, ()), DROP_HEIGHT):
        z = centre[2] + resting_height(spec) + drop
        for yaw in yaws:
            X = RigidTransform(RollPitchYaw(0, 0, yaw), [centre[0], centre[1], z])
            out.append((X, X @ X_OB))
    return out


def _raised(X: RigidTransform, dz: float) -> RigidTransform:
    return RigidTransform(X.rotation(), X.translation() + [0, 0, dz])


def free_path(reach, q_from, q_to, q_hand, clearance: float = 0.002):
    """A collision-free joint path from ``q_from`` to ``q_to`` (list of arm
    configurations, ends excluded), or None. First through one via point (the hand
    raised ``VIA_RISES`` above either end, by one IK solve each: two straight
    segments, checked as :meth:`ArmReach.path_is_free`); then by Drake's
    ``KinematicTrajectoryOptimization`` (B-spline, minimum duration + length, joint
    position and velocity limits, the minimum-distance constraint at sample points;
    10 control points and 20 samples, then 14 and 28; each solve counted as
    ``PATH_SEARCH_COST`` IK solves against ``reach.ik_limit``), checked densely."""
    path = _via_path(reach, q_from, q_to, q_hand, clearance)
    if path is not None:
        return path
    for num_control_points, samples in ((10, 20), (14, 28)):
        if reach.ik_limit is not None and reach.ik_solves + PATH_SEARCH_COST > reach.ik_limit:
            return None
        reach.ik_solves += PATH_SEARCH_COST
        path = _kto_path(reach, q_from, q_to, q_hand, num_control_points, samples, clearance)
        if path is not None:
            return path
    return None


def _via_path(reach, q_from, q_to, q_hand, clearance):
    """``[q_via]``: arm joints with the hand ``VIA_RISES`` above where it is at
    ``q_from`` or ``q_to`` from which both straight segments are collision free, or
    None (an arm whose IK moves the wrist is not tried: the hand's posture would
    change on the way)."""
    if _free_joints(reach):
        return None
    for rise in VIA_RISES:
        for q_end in (q_from, q_to):
            if reach.budget_spent():
                return None
            X = _raised(reach.hand_pose(q_end), rise)
            result = reach.solve(X, q_end, q_hand, clearance=clearance)
            if result.ok and reach.path_is_free(q_from, result.q, q_hand) and \
                    reach.path_is_free(result.q, q_to, q_hand):
                return [result.q]
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


def _check_target(scenario, target: str, kind: str) -> None:
    """A PickPlanningError unless pick grasps a ``kind`` and the box has its hole."""
    if kind not in CLASS_ORDER:
        raise PickPlanningError(f"{target}: no grasp for a {kind} (pick takes "
                                f"{sorted(CLASS_ORDER)})")
    if kind not in hole_centres(scenario):
        raise PickPlanningError(f"{target}: the sorting box has no hole for a {kind} "
                                f"(sorting_box.holes)")


def plan_pick(scenario, reach, target: str, kind: str, size: float, X_WO: RigidTransform,
              q_start, classes=None, grasp_budget: float | None = GRASP_BUDGET,
              total_budget: float | None = GRASP_TOTAL_BUDGET,
              grasp_db: GraspDatabase | None = None,
              ik_budget: int | None = PLAN_IK_BUDGET) -> PickPlan:
    """Plans picking ``target`` (a ``kind`` of ``size`` at ``X_WO``) into its hole
    (see the module doc). ``reach`` is an :class:`~handle_drake.apps.pick.reach.ArmReach`
    of the scenario ignoring ``target``; ``q_start`` the arm's joints now;
    ``grasp_budget`` the seconds each class's grasp search may take, ``total_budget``
    all of them together (None: unbounded).

    The grasps come from ``grasp_db`` (default: the shipped :data:`GRASP_DB`; an
    empty ``GraspDatabase()`` for none): an object within ``SIZE_TOLERANCE`` of a
    catalogue size is planned as that catalogue object resting on the table, so
    every class's grasp is a stored one and only the arm's IK and paths are
    computed. Another size of a stored class and kind gets the nearest stored grasp
    adapted to it (``adapt_grasp``); a class and kind the database lacks is searched
    (within the budgets) and the answer reused for the rest of the process
    (``plan_grasp``'s ``cache``)."""

    _check_target(scenario, target, kind)
    ratio = scenario.hand.coupling_ratio or 1.0
    hand = get_hand_spec(scenario.hand.kind)
    base = scenario.hand.mount.X_WB.GetDeterministicValue().translation()
    grasp_db = default_grasp_database() if grasp_db is None else grasp_db
    size, X_WO = _as_catalogue(scenario, kind, size, X_WO)
    spec = _spec(scenario, kind, size)
    q_start = np.asarray(q_start, dtype=float)
    r = _PickRequest(scenario, reach, target, kind, spec, X_WO, q_start, ratio, hand, base,
                     grasp_db)
    first, limit = reach.ik_solves, reach.ik_limit
    reach.ik_limit = None if ik_budget is None else first + int(ik_budget)
    try:
        plan = _plan_classes(r, classes, grasp_budget, total_budget, ik_budget)
    finally:
        reach.ik_limit = limit
    plan.ik_solves = reach.ik_solves - first
    return plan


def _plan_classes(r, classes, grasp_budget, total_budget, ik_budget) -> PickPlan:
    """plan_pick's search over the grasp classes (see there)."""
    target, kind, reach = r.target, r.kind, r.reach
    # First every class from the database (stored or adapted: no search, no clock), then
    # the searches within the budgets, for the classes the database could not serve.
    order = list(classes or CLASS_ORDER[kind])
    passes = [(cls, False) for cls in order] + [(cls, True) for cls in order]
    for cls, search in passes:
        if search and not r.attempts.get(cls, "").startswith(_NOT_STORED):
            continue  # the database served it (the arm did not reach it), or no size fits
        budget = grasp_budget
        if search and total_budget is not None:
            left = total_budget - r.searched
            if left <= 0:
                r.attempts[cls] = ("not tried: the grasp planning budget "
                                   f"({total_budget} s) is spent")
                continue
            budget = left if budget is None else min(budget, left)
        if reach.budget_spent():
            r.attempts[cls] = f"not tried: the planning budget ({ik_budget} IK solves) is spent"
            continue
        found = _class_grasp(r, cls, search, budget)
        if found is not None:
            plan = _plan_with_grasp(r, cls, *found)
            if plan is not None:
                return plan
    raise PickPlanningError(f"{target} ({kind}): no reachable pick; " + "; ".join(
        f"{c}: {why}" for c, why in r.attempts.items()))


@dc.dataclass
class _PickRequest:
    """One :func:`plan_pick` call: the object, arm and hand it plans for, and its
    tallies so far (the reasons per class, the seconds, the grasp log and the
    seconds of grasp searches, which ``total_budget`` bounds)."""

    scenario: object
    reach: object
    target: str
    kind: str
    spec: ObjectSpec
    X_WO: RigidTransform
    q_start: np.ndarray
    ratio: float
    hand: object
    base: np.ndarray
    grasp_db: GraspDatabase
    attempts: dict = dc.field(default_factory=dict)
    seconds: dict = dc.field(default_factory=lambda: {"grasp": 0.0, "ik": 0.0, "path": 0.0})
    log: list = dc.field(default_factory=list)
    searched: float = 0.0


def _class_grasp(r: _PickRequest, cls, search: bool, budget):
    """``(grasp, source)`` of class ``cls`` on the object: from the database (stored or
    adapted) or, with ``search``, searched within ``budget`` s; source one of
    ``GRASP_SOURCES``. None when there is none (the reason in ``r.attempts``)."""
    start = time.perf_counter()
    stored = _grasp_key(cls, r.spec, r.X_WO.translation()[2] - r.scenario.table.top_height,
                        r.ratio) in r.grasp_db
    if not stored and not search:
        # Adapting takes 0.1-0.8 s a class: first whether the arm reaches the stored
        # grasp it would start from (its hand poses are within mm of the adapted one's).
        reason = _stored_grasp_unreachable(r.scenario, r.reach, cls, r.kind, r.spec, r.X_WO,
                                           r.base, r.ratio, r.hand, r.grasp_db, r.q_start,
                                           r.seconds)
        if reason:
            r.attempts[cls] = reason
            r.log.append((cls, "unreachable", time.perf_counter() - start))
            r.seconds["grasp"] += time.perf_counter() - start
            return None
    try:
        grasp = _plan_grasp(cls, r.spec, r.X_WO, table_height=r.scenario.table.top_height,
                           reach_direction=r.X_WO.translation()[:2] - r.base[:2],
                           coupling_ratio=r.ratio, time_budget=budget if search else None,
                           database=r.grasp_db, search=search)
    except ValueError as error:
        r.attempts[cls] = f"no grasp plan: {error}"
        spent = time.perf_counter() - start
        r.seconds["grasp"] += spent
        r.searched += spent if search else 0.0
        r.log.append((cls, "failed", spent))
        return None
    spent = time.perf_counter() - start
    r.seconds["grasp"] += spent
    r.searched += spent if search else 0.0
    source = "stored" if stored else "adapted" if grasp.adapted_from else "searched"
    r.log.append((cls, source, spent))
    return grasp, source


def _plan_with_grasp(r: _PickRequest, cls, grasp, source) -> PickPlan | None:
    """The PickPlan of ``cls``'s ``grasp`` at the first turn (``_turns``) whose whole
    chain the arm reaches, or None (the reasons in ``r.attempts``)."""
    reasons, needs_search = [], []
    # Every turn with straight joint paths first, then the turns that only lacked one
    # with the path search (KinematicTrajectoryOptimization: a failing one took
    # 11-134 s on held-out seed 505, whose grasp turned 20 deg needs no search).
    for search_paths in (False, True):
        for turn in (_turns(r.kind, cls) if not search_paths else needs_search):
            turned = grasp
            if turn:
                try:
                    turned = _plan_grasp(cls, r.spec, _turned(r.X_WO, turn),
                                        table_height=r.scenario.table.top_height,
                                        reach_direction=r.X_WO.translation()[:2] - r.base[:2],
                                        coupling_ratio=r.ratio, database=r.grasp_db,
                                        search=False)
                except ValueError:
                    continue
            waypoints, X_release, reason = _pick_chain(
                r.scenario, r.reach, r.kind, r.spec, r.X_WO, turned, r.q_start, r.ratio,
                r.hand, r.seconds, search_paths)
            if not reason:
                return PickPlan(r.target, r.kind, cls, turned, waypoints, r.X_WO, X_release,
                                r.seconds, r.attempts, source, r.log, _free_joints(r.reach))
            if reason.startswith(_NO_STRAIGHT):
                needs_search.append(turn)
            else:
                reasons.append(reason)
            if r.reach.budget_spent():
                break
    reasons = reasons or ["no grasp at any turn"]
    r.attempts[cls] = reasons[0] if len(set(reasons)) == 1 else "; ".join(
        dict.fromkeys(reasons))
    return None


def _stored_grasp_unreachable(scenario, reach, cls, kind, spec, X_WO, base, ratio, hand,
                              grasp_db, q_start, seconds) -> str:
    """Why the arm reaches the pre-grasp and grasp poses of no turn (``GRASP_TURNS``) of
    the class's stored grasp on the catalogue object of this kind nearest in size
    (resting where ``X_WO`` stands), or "" (it reaches one, or there is no such stored
    grasp to judge by)."""
    box = scenario.sorting_box
    sizes = [h.size for h in (box.holes if box is not None else []) if h.kind == kind
             and h.size]
    if not sizes:
        return ""
    known = ObjectSpec(kind=kind, size=float(min(sizes, key=lambda v: abs(v - spec.size))))
    z = scenario.table.top_height + resting_height(known)
    X_known = RigidTransform(X_WO.rotation(), [*X_WO.translation()[:2], z])
    reason = ""
    for turn in _turns(kind, cls):
        try:
            grasp = _plan_grasp(cls, known, _turned(X_known, turn),
                               table_height=scenario.table.top_height,
                               reach_direction=X_WO.translation()[:2] - base[:2],
                               coupling_ratio=ratio, database=grasp_db, search=False)
        except ValueError:
            return ""
        q_open = actuated_to_joint_positions(hand, grasp.preshape_command, ratio)
        chain = [("pregrasp", grasp.X_WB_pregrasp, q_open, grasp.preshape_command),
                 ("grasp", grasp.X_WB, q_open, grasp.preshape_command)]
        symmetry = (kind, (grasp.X_WB.inverse() @ X_known).translation())  # as _pick_chain
        reason = _solve_chain(reach, chain, [Waypoint("start", q_start,
                                                      grasp.preshape_command)], seconds,
                              symmetry)
        if not reason:
            return ""
    return f"{reason} (of the stored {known.size * 100:.1f} cm grasp, before adapting it)"


def _turns(kind: str, cls: str) -> tuple:
    """The turns (rad) of ``cls``'s grasp on a ``kind`` tried in turn."""
    return GRASP_TURNS.get(kind, (0.0,)) if cls in TURNED_CLASSES else (0.0,)


def _turned(X: RigidTransform, yaw: float) -> RigidTransform:
    """``X`` turned by ``yaw`` about its own vertical axis."""
    return RigidTransform(X.rotation() @ RotationMatrix.MakeZRotation(yaw), X.translation())


def _pick_chain(scenario, reach, kind, spec, X_WO, grasp, q_start, ratio, hand, seconds,
                search_paths: bool = True):
    """``(waypoints, X_WO_release, reason)`` of one grasp: the arm's IK of the pre-grasp,
    grasp, lift, carry and release (each turn over the hole in turn) and the paths
    between them (``search_paths`` False: straight joint segments only); ``reason``
    empty when the whole chain exists."""
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
        reason = _connect(reach, waypoints, seconds, search_paths)
    return waypoints, X_release, reason


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
    if _free_joints(reach):
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
        result = reach.solve_from_seeds(X, [previous.q, waypoints[0].q], q_hand, tries=0,
                                        **options)
        seconds["ik"] += result.seconds
        if not result.ok:
            return f"no IK for the {label} pose" + (
                f" ({BUDGET_SPENT})" if result.message == BUDGET_SPENT else "")
        if result.q_hand is not None:  # an arm with < 6 joints moved the hand's wrist
            hand_names = reach.hand_spec.joint_names
            command = _with_wrist(reach, command, None, {
                n: result.q_hand[hand_names.index(n)] for n in reach.free_hand_joints})
        waypoints.append(Waypoint(label, result.q, command))
    return ""


def _free_joints(reach) -> tuple[str, ...]:
    """The hand joints ``reach``'s IK moves (its wrist: an arm with fewer than six
    joints, :class:`handle_drake.apps.pick.reach.ArmReach`), else ()."""
    return tuple(getattr(reach, "free_hand_joints", ()))


def _with_wrist(reach, command, source=None, values=None):
    """``command`` with the IK's wrist joints (``reach.free_hand_joints``, arms with
    fewer than six joints) from ``values`` (name -> rad) or the command ``source``."""
    free = _free_joints(reach)
    if not free or (source is None and values is None):
        return command
    names = list(reach.hand_spec.actuated_joint_names)
    out = np.array(command, dtype=float)
    for name in free:
        i = names.index(name)
        out[i] = values[name] if values is not None else source[i]
    return out


_NO_STRAIGHT = "no straight collision-free path"


def _connect(reach, waypoints, seconds, search_paths: bool = True) -> str:

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
            if not search_paths:
                return f"{_NO_STRAIGHT} from {a.label} to {b.label}"
            path = free_path(reach, a.q, b.q, q_hand)
            if path is None:
                return f"no collision-free path from {a.label} to {b.label}"
            b.path = path
        return ""
    finally:
        seconds["path"] += time.perf_counter() - start
