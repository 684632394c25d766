"""The grasp planner's time budget and its cache of hand-IK answers (issue 33)."""

import numpy as np
import pytest
from pydrake.math import RigidTransform, RollPitchYaw

from handle_drake.grasp import planning
from handle_drake.grasp.planning import (
    GraspPlanningError,
    GraspPlanningTimeout,
    clear_solution_cache,
    plan_grasp,
    resting_pose,
)

SPHERE = ("sphere", 0.06)


@pytest.fixture
def counted(monkeypatch):
    """Counts the hand-IK searches (``_solve_contacts`` calls) with an empty cache."""
    clear_solution_cache()
    calls = []
    solve = planning._solve_contacts

    def counting(*args, **kwargs):
        calls.append(args[0].grasp_class)
        return solve(*args, **kwargs)

    monkeypatch.setattr(planning, "_solve_contacts", counting)
    yield calls
    clear_solution_cache()


def test_an_exhausted_budget_stops_the_search_and_is_not_cached(counted):
    with pytest.raises(GraspPlanningTimeout, match="time budget"):
        plan_grasp("tripod", SPHERE, resting_pose(*SPHERE), time_budget=1e-6)
    assert issubclass(GraspPlanningTimeout, GraspPlanningError)
    # The timed-out class has no cached answer: without a budget it is searched again.
    plan = plan_grasp("tripod", SPHERE, resting_pose(*SPHERE))
    assert len(counted) == 2 and plan.contact_error < 1.5e-3


@pytest.mark.parametrize("budget", [0.0, -1.0, float("nan")])
def test_a_bad_budget_is_refused(budget):
    with pytest.raises(ValueError, match="time_budget"):
        plan_grasp("tripod", SPHERE, resting_pose(*SPHERE), time_budget=budget)


def test_the_cached_answer_is_the_one_a_fresh_search_gives_elsewhere(counted):
    first = plan_grasp("tripod", SPHERE, resting_pose(*SPHERE), reach_direction=(1, 0))
    X_WO = RigidTransform(RollPitchYaw(0, 0, 0.7), [0.2, -0.15, resting_pose(*SPHERE)
                                                    .translation()[2]])
    cached = plan_grasp("tripod", SPHERE, X_WO, reach_direction=(0.3, 1.0))
    assert len(counted) == 1  # the second plan reused the first's hand IK
    fresh = plan_grasp("tripod", SPHERE, X_WO, reach_direction=(0.3, 1.0), cache=False)
    assert len(counted) == 2
    np.testing.assert_allclose(cached.X_WB.GetAsMatrix4(), fresh.X_WB.GetAsMatrix4(),
                               atol=1e-9)
    np.testing.assert_allclose(cached.X_WB_pregrasp.GetAsMatrix4(),
                               fresh.X_WB_pregrasp.GetAsMatrix4(), atol=1e-9)
    for name in ("preshape_command", "grasp_command", "close_command"):
        np.testing.assert_allclose(getattr(cached, name), getattr(fresh, name), atol=1e-9)
    # A different size, height or class is a different search.
    plan_grasp("tripod", ("sphere", 0.055), resting_pose("sphere", 0.055))
    assert len(counted) == 3
    assert not np.allclose(first.X_WB.translation(), cached.X_WB.translation())
