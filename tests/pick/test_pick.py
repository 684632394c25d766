"""Pick and place: random scenes, the pick plan, and one whole pick into the box."""

import math

import numpy as np
import pytest

from handle_drake.apps.pick.plan import DROP_HEIGHT, plan_pick
from handle_drake.apps.pick.reach import ArmReach
from handle_drake.apps.pick.scenes import GAP, REGION, random_scene
from handle_drake.base.models import diagrams_dir
from handle_drake.cli import main
from handle_drake.scenario import validate_scenario
from handle_drake.scene.config import (
    footprint_radius,
    hole_centres,
    initial_pose,
    scene_objects,
    spec_of,
)

PATH = diagrams_dir() / "hamburg_setup.yaml"  # the scenario of conftest's ``hamburg``


def test_random_scenes_are_seeded_valid_and_spread(hamburg):
    counts = set()
    for seed in range(8):
        scene = random_scene(hamburg, seed)
        again = random_scene(hamburg, seed)
        objects = scene_objects(scene)
        np.testing.assert_array_equal(
            [np.asarray(o.X_WO.translation, dtype=float) for _, o in objects],
            [np.asarray(o.X_WO.translation, dtype=float) for _, o in scene_objects(again)])
        assert 2 <= len(objects) <= 5
        counts.add(len(objects))
        validate_scenario(scene)  # no overlaps, none on the box
        for i, (_, a) in enumerate(objects):
            pa = np.asarray(a.X_WO.translation[:2], dtype=float)
            assert np.all(pa >= REGION[0]) and np.all(pa <= REGION[1])
            for _, b in objects[i + 1:]:
                pb = np.asarray(b.X_WO.translation[:2], dtype=float)
                gap = math.dist(pa, pb) - footprint_radius(spec_of(a)) - footprint_radius(
                    spec_of(b))
                assert gap >= GAP - 1e-9
    assert len(counts) >= 2


def test_pick_plan_reaches_every_pose_and_releases_over_the_hole(hamburg):
    name, sphere = next((n, o) for n, o in scene_objects(hamburg) if o.kind == "sphere")
    reach = ArmReach(hamburg, ignore=(name,))
    X_WO = initial_pose(sphere, hamburg.table)
    plan = plan_pick(hamburg, reach, name, "sphere", sphere.size, X_WO,
                     hamburg.hand.mount.initial_position)
    by_label = {w.label: w for w in plan.waypoints}
    assert list(by_label) == ["start", "pregrasp", "grasp", "close", "lift", "carry",
                              "release", "open"]
    grasp = plan.grasp
    for label, X in (("pregrasp", grasp.X_WB_pregrasp), ("grasp", grasp.X_WB),
                     ("lift", grasp.lifted())):
        X_reached = reach.hand_pose(by_label[label].q)
        assert np.linalg.norm(X_reached.translation() - X.translation()) < 0.004
    # Released: the object (rigidly in the hand as planned) centred over its hole,
    # its bottom DROP_HEIGHT above the lid.
    X_OB = X_WO.inverse() @ grasp.X_WB
    X_WO_release = reach.hand_pose(by_label["release"].q) @ X_OB.inverse()
    hole = hole_centres(hamburg)["sphere"]
    np.testing.assert_allclose(X_WO_release.translation()[:2], hole[:2], atol=0.004)
    assert X_WO_release.translation()[2] == pytest.approx(
        hole[2] + sphere.size / 2 + DROP_HEIGHT, abs=0.004)
    for w in plan.waypoints[1:]:
        assert np.all(w.q >= np.array(reach.spec.lower)) and np.all(
            w.q <= np.array(reach.spec.upper))
    assert plan.seconds["ik"] + plan.seconds["path"] < 10.0  # bounded (timing: benchmark)


def test_each_grasp_class_gets_a_time_budget(hamburg):
    from handle_drake.apps.pick.plan import CLASS_ORDER, PickPlanningError
    from handle_drake.grasp.database import GraspDatabase
    from handle_drake.grasp.planning import clear_solution_cache

    empty = GraspDatabase()  # the search the budget bounds, not the stored grasps

    clear_solution_cache()  # a cached answer would skip the search the budget bounds
    name, sphere = next((n, o) for n, o in scene_objects(hamburg) if o.kind == "sphere")
    reach = ArmReach(hamburg, ignore=(name,))
    with pytest.raises(PickPlanningError) as error:
        plan_pick(hamburg, reach, name, "sphere", sphere.size,
                  initial_pose(sphere, hamburg.table), hamburg.hand.mount.initial_position,
                  grasp_budget=1e-6, total_budget=None, grasp_db=empty)
    # Every class the sphere's size allows ran out of its budget; the others are too small.
    # (No total budget here: one search's solve overruns its budget, by seconds on a
    # loaded machine, which would spend a total one and leave the next classes untried.)
    timed_out = [c for c in CLASS_ORDER["sphere"] if f"{c}: no grasp plan: time budget"
                 in str(error.value)]
    assert timed_out == ["tripod", "parallel_extension", "palmar_pinch"]
    # A total budget: the first class spends it, the rest are not tried.
    with pytest.raises(PickPlanningError) as error:
        plan_pick(hamburg, reach, name, "sphere", sphere.size,
                  initial_pose(sphere, hamburg.table), hamburg.hand.mount.initial_position,
                  grasp_budget=None, total_budget=1e-6, grasp_db=empty)
    assert "tripod: no grasp plan: time budget" in str(error.value)
    assert "parallel_extension: not tried: the grasp planning budget" in str(error.value)


def test_bystanders_are_welded_where_they_rest_and_the_target_stays_free(hamburg):
    import dataclasses as dc

    from handle_drake.apps.pick.execute import weld_bystanders
    from handle_drake.station import GetPlant, MakeHandStation

    scene = dc.replace(random_scene(hamburg, 3), cameras=[])
    names = [n for n, _ in scene_objects(scene)]
    target = names[-1]
    welded = weld_bystanders(scene, target)
    plant = GetPlant(MakeHandStation(welded))
    free = GetPlant(MakeHandStation(scene))
    assert free.num_positions() - plant.num_positions() == 7 * (len(names) - 1)
    context = plant.CreateDefaultContext()
    for name, o in scene_objects(welded):
        body = plant.get_body(plant.GetBodyIndices(plant.GetModelInstanceByName(name))[0])
        assert body.is_floating_base_body() == (name == target)
        np.testing.assert_allclose(
            plant.EvalBodyPoseInWorld(context, body).translation(),
            initial_pose(o, scene.table).translation(), atol=1e-12)
    with pytest.raises(ValueError, match="not an object"):
        weld_bystanders(scene, "object_9")


def test_the_plant_judge_wants_every_collision_point_in_the_cavity_at_rest(hamburg):
    """The separate judge (tests/pick/pick_judge.py) on states set by hand: the scene
    as it starts (on the table), a cuboid resting inside the box on its floor, the
    same falling, the same held in the air, and one whose centre is inside (the app's
    ``in_box`` says yes) but whose top reaches through the lid."""
    import dataclasses as dc

    from pick_judge import judge_in_box
    from pydrake.math import RigidTransform

    from handle_drake.scene.config import box_pose, in_box
    from handle_drake.station import GetPlant, MakeHandStation

    scene = dc.replace(hamburg, cameras=[])
    name = next(n for n, o in scene_objects(scene) if o.kind == "cuboid")
    plant = GetPlant(MakeHandStation(scene))
    context = plant.CreateDefaultContext()
    body = plant.get_body(plant.GetBodyIndices(plant.GetModelInstanceByName(name))[0])
    start = judge_in_box(scene, name, plant.GetPositionsAndVelocities(context))
    assert not start["in_cavity"] and start["at_rest"] and start["points"] == 8 + 4 * 6
    box = scene.sorting_box
    X_WB = box_pose(scene)
    for z, moving, expected in ((box.wall + 0.046, False, (True, True)),
                                (box.wall + 0.046, True, (True, False)),
                                (box.wall + 0.06, False, (True, False)),  # in the air
                                (box.size[2] - box.wall - 0.01, False, (False, False))):
        p = X_WB @ np.array([0.05, 0.0, z])
        plant.SetFreeBodyPose(context, body, RigidTransform(X_WB.rotation(), p))
        plant.SetFreeBodySpatialVelocity(context, body, _spatial(0.05 if moving else 0.0))
        verdict = judge_in_box(scene, name, plant.GetPositionsAndVelocities(context))
        assert (verdict["in_cavity"], verdict["at_rest"]) == expected, z
        assert in_box(scene, p)  # the app's centre test says "in" each time


def _spatial(speed):
    from pydrake.multibody.math import SpatialVelocity

    return SpatialVelocity(np.zeros(3), np.array([0.0, 0.0, -speed]))


@pytest.mark.parametrize("close", ["reactive", "scripted"])
def test_pick_command_puts_the_sphere_in_the_box(close, capsys, monkeypatch):
    """The command says "in the box" (exit 0) and the plant agrees: its final state,
    judged by separate code (every collision point of the ball in the cavity, at
    rest)."""
    import json

    from pick_judge import FinalState, judge_in_box

    from handle_drake.apps.pick import execute

    final, runs = FinalState(), []

    def watched(scenario, plan, **kwargs):
        runs.append((scenario, plan.target))
        return run(scenario, plan, **dict(kwargs, monitor=final))

    run = execute.execute_pick
    monkeypatch.setattr(execute, "execute_pick", watched)
    flags = ["--scripted-close"] if close == "scripted" else []
    code = main(["pick", str(PATH), "--true-poses", "--kind", "sphere", "--json", *flags])
    captured = capsys.readouterr()
    lines = captured.out.strip().splitlines()
    assert lines[-1] == "in the box" and code == 0
    result = json.loads("\n".join(lines[:-1]))
    # A line per phase as it ended (on stderr under --json), in order, with its time;
    # the simulated phases add up to the whole simulated run.
    phases = ["perceive", "plan", "approach", "close", "lift", "carry", "release"]
    progress = captured.err.strip().splitlines()
    assert [line.split()[0] for line in progress] == phases
    assert [p["phase"] for p in result["phases"]] == phases
    assert all(p["wall_s"] >= 0 for p in result["phases"])
    simulated = [p["sim_s"] for p in result["phases"] if "sim_s" in p]
    assert len(simulated) == 5 and all(t > 0 for t in simulated)
    assert sum(simulated) == pytest.approx(result["sim_s"], abs=5e-3)
    assert result["status"] == "in_box"
    (scenario, target), = runs
    verdict = judge_in_box(scenario, target, final.x)
    assert final.t == pytest.approx(result["sim_s"])
    assert verdict["in_cavity"] and verdict["at_rest"], str(verdict)
    assert result["close"] == close and result["grasp_stored"]
    # The ball was located in the hand after the lift and the release planned for it.
    assert result["release_corrected"] and result["in_hand_contacts"] >= 2
    if close == "reactive":
        # The tactile close ran: the tripod's first, middle finger and thumb (channels
        # 0, 1, 4) each stopped on a touch part-way, the idle ring and little fingers
        # never closed; then the squeeze and the lift.
        assert result["close_mode"] == "LIFT"
        assert result["fingers_touched"] == [True, True, False, False, True]
        closing = np.array(result["closing_at_squeeze"])
        assert np.all((closing[[0, 1, 4]] > 0.1) & (closing[[0, 1, 4]] < 1.0))
    else:
        assert "close_mode" not in result


@pytest.mark.parametrize("override, message", [
    # Nothing the box has a hole for (Hamburg's: cylinder, cuboid, star prism, sphere): a
    # mug and a wine glass only.
    ("{object: {kind: mug, size: 0.06, X_WO: {translation: [-0.12, -0.12, 0]}}, "
     "objects: [{kind: wine_glass, size: 0.06, X_WO: {translation: [0.12, 0.0, 0]}}]}",
     "no pickable object on the table (found ['mug', 'wine_glass'])"),
    # A ball on the table's far corner, 1.5 m from the arm's base: no class reachable.
    ("{object: {kind: sphere, size: 0.06, X_WO: {translation: [0.45, -0.4, 0]}}, "
     "objects: []}", "object (sphere): no reachable pick; tripod: no IK"),
])
def test_pick_with_nothing_to_attempt_exits_3_with_the_whole_reason(override, message,
                                                                    capsys):
    code = main(["pick", str(PATH), "--true-poses", "--override", override])
    out = capsys.readouterr().out.strip().splitlines()
    assert code == 3
    assert out[-1].startswith("not in the box: ") and message in out[-1]
    if "no reachable pick" in message:  # every class's reason, none cut short
        for cls in ("parallel_extension", "palmar_pinch"):
            assert f"{cls}: " in out[-1]
        assert [line.split()[0] for line in out[:2]] == ["perceive", "plan"]


@pytest.mark.parametrize("args, message", [
    (["--override", "hand: {mount: !FloatingWrist {}}"], "hand.mount must be an !Arm"),
    (["--override", "sorting_box: null"], "--place box: the scenario has no sorting_box"),
    (["--override", "cameras: []"], "no camera to perceive with"),
    (["--true-poses", "--object", "9"], "--object: 9 is not one of the 4 objects"),
    (["--true-poses", "--object", "-1"], "--object: -1 is not one of the 4 objects"),
])
def test_pick_refuses_bad_input_with_exit_2(args, message, capsys):
    code = main(["pick", str(PATH), *args])
    assert code == 2
    assert message in capsys.readouterr().err


@pytest.mark.parametrize("seed", ["-3", str(2**63), "1.5"])
def test_pick_scene_seed_out_of_range_is_refused_by_the_parser(seed, capsys):
    with pytest.raises(SystemExit) as stop:
        main(["pick", str(PATH), "--scene-seed", seed])
    assert stop.value.code == 2
    assert "--scene-seed: expected an integer in 0..2**63-1" in capsys.readouterr().err


def test_free_path_goes_around_what_the_straight_segment_hits(hamburg):
    """Hand low over the table on either side of the sorting box: the straight joint
    segment drives it through the box; free_path finds a way (a via point with the hand
    raised, else KinematicTrajectoryOptimization), every segment of it collision free
    and within the joint limits."""
    import dataclasses as dc

    from pydrake.math import RigidTransform, RollPitchYaw

    from handle_drake.apps.pick.plan import free_path

    reach = ArmReach(dc.replace(hamburg, cameras=[]))
    hand = np.zeros(len(reach.hand_spec.joint_names))
    ready = np.array(hamburg.hand.mount.initial_position)
    a = reach.solve_from_seeds(RigidTransform(RollPitchYaw(np.pi / 2, 0, np.pi / 2),
                                              [-0.4, -0.03, 0.13]), [ready], hand)
    b = reach.solve_from_seeds(RigidTransform(RollPitchYaw(np.pi / 2, 0, np.pi / 2),
                                              [-0.4, 0.6, 0.13]), [a.q], hand)
    assert a.ok and b.ok
    assert not reach.path_is_free(a.q, b.q, hand)
    path = free_path(reach, a.q, b.q, hand)
    assert path is not None and len(path) >= 1
    points = [a.q, *path, b.q]
    for p, q in zip(points, points[1:], strict=False):
        assert reach.path_is_free(p, q, hand)
        assert np.all(q >= np.array(reach.spec.lower) - 1e-6)
        assert np.all(q <= np.array(reach.spec.upper) + 1e-6)


def _geometries(plant, name):
    instance = plant.GetModelInstanceByName(name)
    return plant.CollectRegisteredGeometries(
        [plant.get_body(i) for i in plant.GetBodyIndices(instance)])


def test_idle_contact_filter_excludes_only_the_pairs_no_pick_has(hamburg):
    """Arm against table, box and objects, and the resting bystanders against the box
    and each other, are excluded; every pair the hand or the picked object can make,
    and the bystanders on the table, stays."""
    import dataclasses as dc
    import itertools

    from pydrake.geometry import Role

    from handle_drake.apps.pick.execute import filter_idle_contacts
    from handle_drake.station import GetPlant, MakeHandStation

    scene = dc.replace(random_scene(hamburg, 0), cameras=[])
    names = [n for n, _ in scene_objects(scene)]
    target, bystanders = names[-1], names[:-1]
    station = MakeHandStation(scene)
    plant = GetPlant(station)
    context = station.CreateDefaultContext()

    def inspector():
        return station.GetOutputPort("query_object").Eval(context).inspector()

    def filtered(a, b):
        ins = inspector()
        ga = ins.GetGeometryIds(_geometries(plant, a), Role.kProximity)
        gb = ins.GetGeometryIds(_geometries(plant, b), Role.kProximity)
        assert ga and gb
        return [ins.CollisionFiltered(g, h) for g in ga for h in gb]

    excluded = ([("arm", n) for n in ("table", "sorting_box", *names)]
                + [(n, "sorting_box") for n in bystanders]
                + list(itertools.combinations(bystanders, 2)))
    kept = ([("hand", n) for n in ("table", "sorting_box", *names)]
            + [(target, n) for n in ("table", "sorting_box", *bystanders)]
            + [(n, "table") for n in bystanders])
    # Before: each pair is simulated (the arm's base, welded to the world like the
    # table and the box, is the plant's own exclusion).
    for a, b in excluded:
        assert not all(filtered(a, b)), (a, b)
    for a, b in kept:
        assert not any(filtered(a, b)), (a, b)
    pairs = filter_idle_contacts(station, context, target)
    assert sorted(pairs) == sorted(excluded)
    for a, b in excluded:
        assert all(filtered(a, b)), (a, b)
    for a, b in kept:
        assert not any(filtered(a, b)), (a, b)
    with pytest.raises(ValueError, match="not an object"):
        filter_idle_contacts(station, context, "object_9")


def test_the_idle_contact_filter_leaves_a_pick_unchanged(hamburg):
    """The same plan simulated with every pair and with the filter: the same outcome,
    the picked object's final position equal to 1e-6 m (bitwise here: the filtered
    pairs never touch, so the contact problem is the same)."""
    import dataclasses as dc

    from handle_drake.apps.pick.execute import execute_pick

    scene = dc.replace(random_scene(hamburg, 1), cameras=[])
    name, target = next((n, o) for n, o in scene_objects(scene) if o.kind == "sphere")
    reach = ArmReach(scene, ignore=(name,))
    plan = plan_pick(scene, reach, name, "sphere", target.size,
                     initial_pose(target, scene.table), scene.hand.mount.initial_position)
    every = execute_pick(scene, plan)
    filtered = execute_pick(scene, plan, filter_contacts=True)
    assert every.in_box and filtered.in_box
    np.testing.assert_allclose(filtered.p_WO_final, every.p_WO_final, atol=1e-6)


def test_a_cuboid_the_arm_cannot_reach_at_its_yaw_is_grasped_turned(hamburg):
    """Development seed 6: the arm reaches no grasp of the nearest cuboid at the
    cuboid's own yaw (IK of the pre-grasp fails from 21 seeds), but the parallel
    extension turned a few degrees about the vertical (GRASP_TURNS): planned with it,
    the arm's joints put the hand where that grasp wants it."""
    import dataclasses as dc

    from handle_drake.apps.pick.plan import GRASP_TURNS

    scene = dc.replace(random_scene(hamburg, 6), cameras=[])
    base = np.array([-1.0, 0.0])
    name, cuboid = min(((n, o) for n, o in scene_objects(scene) if o.kind == "cuboid"),
                       key=lambda t: math.dist(np.asarray(t[1].X_WO.translation[:2],
                                                          dtype=float), base))
    reach = ArmReach(scene, ignore=(name,))
    X_WO = initial_pose(cuboid, scene.table)
    plan = plan_pick(scene, reach, name, "cuboid", cuboid.size, X_WO,
                     scene.hand.mount.initial_position)
    assert plan.grasp_class == "parallel_extension"
    turn = (X_WO.rotation().inverse() @ plan.grasp.X_WO.rotation()).ToAngleAxis()
    angle = turn.angle() * np.sign(turn.axis()[2])
    assert 0.0 < abs(angle) <= max(np.abs(GRASP_TURNS["cuboid"])) + 1e-9
    assert min(abs(angle - t) for t in GRASP_TURNS["cuboid"]) < 1e-9
    by_label = {w.label: w for w in plan.waypoints}
    X_reached = reach.hand_pose(by_label["grasp"].q)
    assert np.linalg.norm(X_reached.translation() - plan.grasp.X_WB.translation()) < 0.004

