"""The pick's physics and planning core: the planning budget (counted in IK solves,
not seconds) and the verdict converged in the plant's time step (issue 49 items 2, 3)."""

import copy
import dataclasses as dc
import math

import numpy as np
import pytest

from handle_drake.apps.pick.plan import plan_pick
from handle_drake.apps.pick.reach import ArmReach
from handle_drake.apps.pick.scenes import random_scene
from handle_drake.scene.config import initial_pose, scene_objects

BASE_XY = np.array([-1.0, 0.0])  # the arm's base (diagrams/hamburg_setup.yaml)


def _nearest(scene, kind):
    """``(name, object)``: the scene's ``kind`` nearest the arm's base."""
    return min(((n, o) for n, o in scene_objects(scene) if o.kind == kind),
               key=lambda t: math.dist(np.asarray(t[1].X_WO.translation[:2], dtype=float),
                                       BASE_XY))


def test_pick_planning_stays_within_its_ik_budget(hamburg, monkeypatch):
    """Development seed 6's cuboid (reached only turned: every turn tried costs IK
    solves): the plan's IK solves, and the SNOPT solves counted independently at
    pydrake's ``Solve`` (one or two per IK solve), stay within ``ik_budget``; with a
    budget too small for any turn the planner stops there and says so."""
    import handle_drake.apps.pick.reach as reach_module
    from handle_drake.apps.pick.plan import PLAN_IK_BUDGET, PickPlanningError

    calls = []
    solve = reach_module.Solve

    def counted(*args, **kwargs):
        calls.append(1)
        return solve(*args, **kwargs)

    monkeypatch.setattr(reach_module, "Solve", counted)
    scene = dc.replace(random_scene(hamburg, 6), cameras=[])
    name, cuboid = _nearest(scene, "cuboid")
    reach = ArmReach(scene, ignore=(name,))
    X_WO = initial_pose(cuboid, scene.table)
    q0 = scene.hand.mount.initial_position
    plan = plan_pick(scene, reach, name, "cuboid", cuboid.size, X_WO, q0)
    # Five poses (pre-grasp, grasp, lift, carry, release) and the turns that failed.
    assert 5 < plan.ik_solves <= PLAN_IK_BUDGET
    assert plan.ik_solves == reach.ik_solves and len(calls) <= 2 * plan.ik_solves
    assert reach.ik_limit is None  # the budget is the plan's only
    small = 3
    before, calls[:] = reach.ik_solves, []
    with pytest.raises(PickPlanningError, match=r"budget \(3 IK solves\) is spent"):
        plan_pick(scene, reach, name, "cuboid", cuboid.size, X_WO, q0, ik_budget=small)
    assert reach.ik_solves - before <= small and len(calls) <= 2 * small


@pytest.mark.slow
def test_a_cuboid_picks_verdict_is_the_same_at_the_step_and_at_half_of_it(hamburg):
    """Reduced (one scene, development seed 2's cuboid, true poses): the same plan
    simulated at the scenario's plant step h and at h/2 ends the same way, judged from
    the plant's final state by separate code (pick_judge: every collision point in the
    box's cavity, at rest), and that way is in the box. The cuboid goes through its hole
    upright: as its bottom comes down to the lid's top it is tilted well under the
    36.9 deg at which a 6 cm cube spans the 84 mm hole (60 (cos t + sin t) = 84) and can
    wedge across it (this plan let go 3 cm above the lid, ``RELEASE_INSERTS`` empty: 21.9
    deg at h, 24.4 at h/2, and this test fails; 1 cm above, the default: it passes)."""
    from pick_judge import TiltAtTheLid, judge_in_box

    from handle_drake.apps.pick.execute import execute_pick
    from handle_drake.scene.config import hole_centres

    scene = dc.replace(random_scene(hamburg, 2), cameras=[])
    name, cuboid = _nearest(scene, "cuboid")
    reach = ArmReach(scene, ignore=(name,))
    plan = plan_pick(scene, reach, name, "cuboid", cuboid.size,
                     initial_pose(cuboid, scene.table), scene.hand.mount.initial_position)
    h = scene.plant_config.time_step
    lid_top = hole_centres(scene)["cuboid"][2]
    verdicts, tilts = [], []
    for step in (h, h / 2):
        config = copy.deepcopy(scene.plant_config)
        config.time_step = step
        stepped = dc.replace(scene, plant_config=config)
        monitor = TiltAtTheLid(name, lid_top + cuboid.size / 2)
        outcome = execute_pick(stepped, plan, reach=reach, monitor=monitor)
        verdict = judge_in_box(stepped, name, monitor.x)
        verdicts.append((verdict["in_cavity"] and verdict["at_rest"], outcome.in_box))
        tilts.append(monitor.tilt)
    assert verdicts == [(True, True), (True, True)], verdicts
    assert all(t is not None and t < 15.0 for t in tilts), tilts
