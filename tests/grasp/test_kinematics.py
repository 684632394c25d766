"""Grasp IK on the Shadow model, and Table 1 re-derived from IK postures."""

from datetime import datetime

import numpy as np
import pytest

from handle_drake.base.hands import get_hand_spec
from handle_drake.grasp.analysis import rederive_table1
from handle_drake.grasp.kinematics import GraspKinematics, object_dims_for
from handle_drake.grasp.recordings import GraspRecords
from handle_drake.grasp.synthetic import posture_prior
from handle_drake.grasp.taxonomy import GraspClass, grasp_centre_palm, palm_to_report_mm

NAMES = get_hand_spec("shadow").joint_names


@pytest.fixture(scope="module")
def kin():
    return GraspKinematics()


def test_lateral_grasp_ik_puts_contacts_on_the_box(kin):
    dims = object_dims_for("box", 0.006, "lateral")
    sol = kin.solve_grasp("lateral", "box", dims, posture_prior("lateral"), min_distance=None)
    assert sol.success
    # Thumb pad and first-finger side on opposite faces: 6 mm apart, symmetric
    # about the object centre.
    pts = kin.contact_points(sol.q, "lateral")
    p_O = {f: sol.X_PO.inverse().multiply(p) for f, p in pts.items()}
    assert p_O["th"][2] == pytest.approx(0.003, abs=1e-5)
    assert p_O["ff"][2] == pytest.approx(-0.003, abs=1e-5)
    np.testing.assert_allclose(kin.grasp_centre(sol.q, "lateral"),
                               0.5 * (pts["th"] + pts["ff"]))
    # Joint limits and the 1:1 coupling hold.
    lo, hi = get_hand_spec("shadow").joint_lower_limits, get_hand_spec("shadow").joint_upper_limits
    assert np.all(sol.q >= lo - 1e-6) and np.all(sol.q <= hi + 1e-6)
    for f in ("FF", "MF", "RF", "LF"):
        assert sol.q[NAMES.index(f"{f}J1")] == pytest.approx(sol.q[NAMES.index(f"{f}J2")], abs=1e-6)


def test_table1_rederived_from_postures_with_known_centres(kin):
    # Postures solved with the object centre held on a known line c(s) =
    # c_ref + slope * (s - s_ref) (the slopes of Table 1's lateral row, c_ref a
    # centre the model reaches): forward kinematics + regression (report
    # section 3.2.1) must give the line back.
    slope = np.array([0.09, 0.14, 0.12])  # mm per mm
    s_ref = 0.016
    free = kin.solve_grasp("lateral", "box", object_dims_for("box", s_ref, "lateral"),
                           posture_prior("lateral"), min_distance=None)
    assert free.success
    c_ref = free.X_PO.translation()
    sizes = [0.010, 0.016, 0.024]
    qs = []
    for s in sizes:
        dims = object_dims_for("box", s, "lateral")
        sol = kin.solve_grasp("lateral", "box", dims, posture_prior("lateral"), tolerance=5e-4,
                              fix_p_PO=c_ref + slope * (s - s_ref), min_distance=None,
                              p_PO_guess=c_ref)
        assert sol.success, s
        qs.append(sol.q)
    rec = GraspRecords(np.array(qs), ["lateral"] * 3, ["box"] * 3,
                       [object_dims_for("box", s, "lateral") for s in sizes], ["t"] * 3,
                       [datetime(2012, 1, 1)] * 3)
    got = np.array(rederive_table1(rec, kin)[GraspClass.LATERAL]["table1"])
    # The contacts may sit 0.5 mm (the IK tolerance) off the antipodal points,
    # so the fitted line is compared over the sizes used, not extrapolated to 0.
    for size in sizes:
        fitted = got[[0, 2, 4]] + got[[1, 3, 5]] * size * 1e3
        truth = palm_to_report_mm(c_ref + slope * (size - s_ref))
        np.testing.assert_allclose(fitted, truth, atol=0.75)
    np.testing.assert_allclose(got[[1, 3, 5]], slope, atol=0.1)
    # Our model's lateral grasp centre vs the report's: same side of the palm.
    assert palm_to_report_mm(c_ref)[1] < 0
    assert np.linalg.norm(c_ref - grasp_centre_palm("lateral", s_ref)) < 0.05


def test_bad_input(kin):
    with pytest.raises(ValueError, match="a sphere needs 1 positive sizes"):
        kin.solve_grasp("tripod", "sphere", (0.04, 0.02), posture_prior("tripod"))
    with pytest.raises(ValueError, match=r"q: expected shape \(24,\)"):
        kin.contact_points(np.zeros(20), "tripod")
    with pytest.raises(ValueError, match="unknown grasp class"):
        kin.solve_grasp("power", "sphere", (0.04,), posture_prior("tripod"))
    with pytest.raises(ValueError, match="shape must be one of"):
        object_dims_for("torus", 0.04)
