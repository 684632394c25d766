"""The picked object located in the hand from the hand's senses (taxels, joints, the
arm's joints; issue 49 item 5, issue 47), against the plant's pose of the object read
here by code of its own, on development scenes (not the evaluation seeds)."""

import numpy as np
import pytest
from pydrake.math import RotationMatrix
from pydrake.multibody.tree import ModelInstanceIndex

from handle_drake.apps.pick import cli, execute
from handle_drake.apps.pick.scenes import EVALUATION_SEEDS, random_scene
from handle_drake.base.hands import get_hand_spec
from handle_drake.station import GetPlant

#: 180 degree turns about each axis leave a cuboid as it was
SYMMETRY = [RotationMatrix(), RotationMatrix.MakeXRotation(np.pi),
            RotationMatrix.MakeYRotation(np.pi), RotationMatrix.MakeZRotation(np.pi)]


class _Located(Exception):
    """Stops the pick once the object is located (the carry is not needed here)."""


def _locate_at_the_lift(hamburg, seed, kind, monkeypatch):
    """Runs the pick of the nearest ``kind`` in scene ``seed`` (true poses) to the lift,
    where the release is corrected; returns ``(X_BO located, X_BO planned, X_BO true,
    pads in contact)``."""
    assert seed not in EVALUATION_SEEDS
    seen = {}
    locate = execute.locate_by_touch

    def spy(station, root_context, scenario, spec, X_OB_planned):
        found = locate(station, root_context, scenario, spec, X_OB_planned)
        plant = GetPlant(station)
        context = plant.GetMyContextFromRoot(root_context)
        hand = plant.GetModelInstanceByName("hand")
        X_WB = plant.GetBodyByName(get_hand_spec("shadow").base_body, hand).EvalPoseInWorld(
            context)
        palm = plant.GetBodyByName("palm", hand).EvalPoseInWorld(context).translation()
        instances = [ModelInstanceIndex(i) for i in range(plant.num_model_instances())]
        bodies = [plant.get_body(plant.GetBodyIndices(i)[0]) for i in instances
                  if plant.GetModelInstanceName(i).startswith("object")]
        body = min(bodies, key=lambda b: np.linalg.norm(
            b.EvalPoseInWorld(context).translation() - palm))
        seen.update(found=found, planned=X_OB_planned.inverse(), spec=spec,
                    truth=X_WB.inverse() @ body.EvalPoseInWorld(context))
        raise _Located

    monkeypatch.setattr(execute, "locate_by_touch", spy)
    with pytest.raises(_Located):
        cli.pick(random_scene(hamburg, seed), true_poses=True, kind=kind)
    assert seen["found"] is not None, "no pad felt the object after the lift"
    return seen["found"][0].inverse(), seen["planned"], seen["truth"], seen["found"][1]


def _errors(X, truth, kind):
    position = np.linalg.norm(X.translation() - truth.translation())
    R = truth.rotation().inverse() @ X.rotation()
    angle = 0.0 if kind == "sphere" else min(abs((R @ S).ToAngleAxis().angle())
                                             for S in SYMMETRY)
    return position, np.degrees(angle)


@pytest.mark.parametrize("seed, kind", [(0, "sphere"), (4, "cuboid")])
def test_the_object_is_located_in_the_hand_from_touch_within_10_mm_and_10_deg(
        hamburg, seed, kind, monkeypatch):
    X, planned, truth, pads = _locate_at_the_lift(hamburg, seed, kind, monkeypatch)
    position, angle = _errors(X, truth, kind)
    assert pads >= 3
    assert position < 0.010 and angle < 10.0, (position, angle)
    # the touch moved the estimate towards the truth from the planned grasp it started at
    assert position < _errors(planned, truth, kind)[0]
