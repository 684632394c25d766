"""The picked object located in the hand from the hand's senses (taxels, joints, the
arm's joints; issue 49 item 5, issue 47), against the plant's pose of the object read
here by code of its own, on development scenes (not the evaluation seeds)."""

from pathlib import Path

import numpy as np
import pytest
from pydrake.math import RotationMatrix
from pydrake.multibody.tree import ModelInstanceIndex

from handle_drake.apps.pick import cli, execute
from handle_drake.apps.pick.scenes import EVALUATION_SEEDS, random_scene
from handle_drake.base.hands import get_hand_spec
from handle_drake.base.models import diagrams_dir
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


def test_the_error_is_scored_up_to_each_kinds_own_symmetry():
    """The symmetries found from each kind's geometry (tests/pick/locate_errors.py) are
    the known ones, and a pose turned by one of them scores no angle error."""
    from locate_errors import pose_errors, symmetries

    from handle_drake.geometry.objects import ObjectSpec
    from handle_drake.scenario import LoadScenario
    from handle_drake.scene.config import hole_spec

    holes = {h.kind: hole_spec(h) for h in LoadScenario(
        filename=diagrams_dir() / "sorter_setup.yaml").sorting_box.holes}
    # a 5-pointed star and a hexagonal prism: their turns about z, each flipped over
    assert len(symmetries(holes["star_prism"])) == 10
    assert len(symmetries(holes["mesh"])) == 12
    assert len(symmetries(holes["mug"])) == 1  # its handle
    assert len(symmetries(ObjectSpec(kind="cuboid", size=0.06,
                                     dimensions=(("height", 0.07),)))) == 4
    R = RotationMatrix.MakeZRotation(2 * np.pi / 5).matrix()
    turned = RotationMatrix.MakeXRotation(0.1).matrix()
    assert pose_errors(holes["star_prism"], np.eye(3), np.zeros(3), R, np.zeros(3))[1] < 1e-6
    assert abs(pose_errors(holes["mug"], np.eye(3), np.zeros(3), R, np.zeros(3))[1] - 72) < 1e-6
    # a round kind's turn about its axis is no error, its axis tilted is
    assert pose_errors(holes["cylinder"], np.eye(3), np.zeros(3), R, [0, 0, 0.003]) == \
        pytest.approx((0.003, 0.0), abs=1e-6)
    assert pose_errors(holes["wine_glass"], np.eye(3), np.zeros(3), turned,
                       np.zeros(3))[1] == pytest.approx(np.degrees(0.1))


@pytest.mark.parametrize("seed, kind", [(610, "cylinder"), (612, "mug"),
                                        (613, "star_prism"), (608, "mesh")])
def test_every_kind_is_located_in_the_hand_within_10_mm_and_10_deg(seed, kind, monkeypatch):
    """The shape sorter's other kinds (development scenes 600-619), each located from its
    own geometry's fit to the touch and scored against the plant's pose up to its
    symmetry (tools/locate_kinds.py). Not every scene is: the tilt about the pinch's axis
    is not seen by the pads on two opposite faces (docs/results/pick.md)."""
    import importlib.util

    from handle_drake.apps.pick.scenes import SORTER_SEEDS
    from handle_drake.scenario import LoadScenario

    assert seed not in SORTER_SEEDS
    monkeypatch.setattr(execute, "LOCATED_KINDS", (*execute.LOCATED_KINDS, kind))
    spec = importlib.util.spec_from_file_location(
        "locate_kinds", Path(__file__).resolve().parents[2] / "tools" / "locate_kinds.py")
    tool = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(tool)
    row = tool.locate_once(LoadScenario(filename=tool.SORTER), seed, kind)
    assert row["status"] == "located", row
    assert row["pads"] >= 3
    assert row["located"][0] < 10.0 and row["located"][1] < 10.0, row
    # the touch moved the estimate towards the truth from the planned grasp
    assert row["located"][0] < row["planned"][0], row
