"""Tables 1-2 of the seed report and the report-frame -> palm-frame conversion."""

import numpy as np
import pytest
from pydrake.multibody.parsing import Parser
from pydrake.multibody.plant import MultibodyPlant

from handle_drake.base.hands import get_hand_spec
from handle_drake.base.models import add_package, model_path
from handle_drake.grasp.taxonomy import (
    GRASP_CLASSES,
    GraspClass,
    approach_palm,
    check_size,
    grasp_centre_palm,
    grasp_centre_report_mm,
    grasp_class,
    grasp_info,
    palm_to_report_mm,
    report_mm_to_palm,
)


def test_eight_classes_with_report_ids():
    ids = {info.name: info.report_id for info in GRASP_CLASSES.values()}
    assert ids == {
        "palmar_pinch": 8, "tripod": 13, "lateral": 15, "writing_tripod": 19,
        "parallel_extension": 21, "adduction_grip": 22, "tip_pinch": 23, "lateral_tripod": 24,
    }


@pytest.mark.parametrize(
    "name, size_mm, expected",
    [
        # Hand-computed from Table 1: c = c0 + delta * size.
        ("tripod", 40.0, (39.27 + 4.0, -69.97 + 11.2, 108.26 + 15.2)),
        ("palmar_pinch", 30.0, (56.32 + 3.3, -81.42 + 10.8, 105.38 + 10.8)),
        ("lateral", 5.0, (52.14 + 0.45, -26.60 + 0.70, 102.82 + 0.60)),
        ("ADDICTION_GRIP", 10.0, (21.64 + 4.5, -33.99 - 4.3, 184.01 - 5.2)),
        ("tip_pinch", 20.0, (53.70 + 1.2, -59.12 + 6.6, 108.95 + 6.6)),
        ("lateral_tripod", 25.0, (37.54 + 3.5, -55.24 + 10.0, 117.61 + 0.75)),
        ("writing_tripod", 10.0, (38.49 + 1.0, -78.52 + 4.7, 102.54 + 4.8)),
        ("PARALLEL_EXT.", 50.0, (43.71 + 5.0, -82.29 + 16.0, 102.17 + 20.0)),
    ],
)
def test_table1_at_size_reproduces_report(name, size_mm, expected):
    np.testing.assert_allclose(grasp_centre_report_mm(name, size_mm), expected, atol=1e-9)


def test_table1_in_palm_frame_metres():
    # Tripod on a 4 cm sphere: (43.27, -58.77, 123.46) mm in the report frame.
    np.testing.assert_allclose(grasp_centre_palm("tripod", 0.04), [0.04327, -0.05877, 0.12346])


def test_frame_conversion_hand_computed_points():
    # The first-finger knuckle joint sits at (0.033, 0, 0.095) m in the palm
    # frame (hand_kinematics.md): on the thumb side (report +x), in the palm
    # plane (y 0), 95 mm along the palm (z).
    np.testing.assert_allclose(report_mm_to_palm([33.0, 0.0, 95.0]), [0.033, 0.0, 0.095])
    # A point 20 mm in front of the palm (palmar = report -y = model -y).
    np.testing.assert_allclose(report_mm_to_palm([0.0, -20.0, 0.0]), [0.0, -0.020, 0.0])
    pts = np.array([[1.0, 2.0, 3.0], [-4.0, 5.0, -6.0]])
    np.testing.assert_allclose(palm_to_report_mm(report_mm_to_palm(pts)), pts)
    with pytest.raises(ValueError, match="expected a point of shape"):
        report_mm_to_palm([1.0, 2.0])


def _palm_points(q_by_name):
    """Forward kinematics of the Shadow model: a few frames in the palm frame."""
    plant = MultibodyPlant(0.0)
    parser = Parser(plant)
    add_package(parser)
    parser.AddModels(model_path(get_hand_spec("shadow").model_relative_path))
    plant.Finalize()
    ctx = plant.CreateDefaultContext()
    for name, value in q_by_name.items():
        plant.GetJointByName(name).set_angle(ctx, value)
    palm = plant.GetFrameByName("palm")
    return {
        n: plant.GetFrameByName(n).CalcPose(ctx, palm).translation()
        for n in ("thbase", "thtip", "fftip", "mftip", "ffknuckle")
    }


def test_report_axes_agree_with_the_model():
    # Report: "x runs to the left (along the stretched thumb)", "z runs along
    # the palm from the wrist to the tip of the middle finger". Check both on
    # the model with all joints at zero (stretched hand).
    p = _palm_points({})
    thumb_dir = palm_to_report_mm(p["thtip"] - p["thbase"])
    thumb_dir /= np.linalg.norm(thumb_dir)
    assert thumb_dir[0] > 0.6  # along +x ...
    assert abs(thumb_dir[1]) < 0.1  # ... in the palm plane
    middle = palm_to_report_mm(p["mftip"])
    assert middle[2] > 150 and abs(middle[0]) < 20 and abs(middle[1]) < 20
    # "y is up from the palm": flexing the fingers (towards the palm) moves
    # the fingertips to report -y, where Table 1 puts every grasp centre.
    flexed = _palm_points({"FFJ3": 1.2, "FFJ2": 0.5, "FFJ1": 0.5})
    assert palm_to_report_mm(flexed["fftip"])[1] < -40
    for info in GRASP_CLASSES.values():
        assert grasp_centre_palm(info.name, 0.02)[1] < 0


def test_approach_vectors_table2():
    np.testing.assert_allclose(approach_palm("tripod"), [0, -1, 0])
    np.testing.assert_allclose(approach_palm("lateral"), [np.sqrt(0.5), 0, np.sqrt(0.5)])
    np.testing.assert_allclose(approach_palm("parallel_extension"),
                               [0, -np.sqrt(0.5), np.sqrt(0.5)])
    for info in GRASP_CLASSES.values():
        assert np.linalg.norm(approach_palm(info.name)) == pytest.approx(1.0)


def test_names_and_aliases():
    assert grasp_class("Writing Tripod") is GraspClass.WRITING_TRIPOD
    assert grasp_class("addition-grip") is GraspClass.ADDUCTION_GRIP
    assert grasp_info(GraspClass.TIP_PINCH).fingers == ("th", "ff")
    with pytest.raises(ValueError, match="unknown grasp class 'power_sphere'.*palmar_pinch"):
        grasp_class("power_sphere")
    with pytest.raises(TypeError, match="must be a str"):
        grasp_class(3)


def test_sizes_are_checked():
    with pytest.raises(ValueError, match="too large for a tripod grasp"):
        check_size("tripod", 0.20)
    with pytest.raises(ValueError, match="positive finite"):
        grasp_centre_palm("tripod", -0.01)
    with pytest.raises(ValueError, match="positive finite"):
        grasp_centre_report_mm("tripod", float("nan"))
    assert check_size("tripod", 0.04) == 0.04
