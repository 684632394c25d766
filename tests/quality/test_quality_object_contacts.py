"""ObjectContacts: a plant's contact results -> per-fingertip contacts in the object frame."""

import numpy as np
import pytest
from pydrake.geometry import AddCompliantHydroelasticProperties, ProximityProperties, Sphere
from pydrake.math import RigidTransform, RollPitchYaw
from pydrake.multibody.plant import (
    AddMultibodyPlant,
    CoulombFriction,
    MultibodyPlantConfig,
)
from pydrake.multibody.tree import SpatialInertia, UnitInertia
from pydrake.systems.analysis import Simulator
from pydrake.systems.framework import DiagramBuilder

from handle_drake.geometry.quality import ContactParams, ObjectContacts, grasp_quality

R_OBJ, R_TIP, PEN = 0.04, 0.01, 1e-3
X_WO = RigidTransform(RollPitchYaw(0.4, -0.3, 1.1), [0.1, -0.2, 0.3])


def build(contact_model="point", pose_input="body_poses", swap=False, sampled=False):
    """A free ball held by two welded fingertip spheres at +-x of the ball (1 mm deep),
    and a third fingertip far away."""
    builder = DiagramBuilder()
    config = MultibodyPlantConfig(time_step=1e-3, discrete_contact_approximation="sap",
                                  contact_model=contact_model,
                                  use_sampled_output_ports=sampled)
    plant, _ = AddMultibodyPlant(config, builder)
    plant.mutable_gravity_field().set_gravity_vector([0, 0, 0])

    def props(r):
        p = ProximityProperties()
        p.AddProperty("material", "coulomb_friction", CoulombFriction(0.5, 0.5))
        if contact_model != "point":
            AddCompliantHydroelasticProperties(r / 2, 1e6, p)
        return p

    ball = plant.AddRigidBody("ball", SpatialInertia(0.1, np.zeros(3),
                                                     UnitInertia.SolidSphere(R_OBJ)))
    plant.RegisterCollisionGeometry(ball, RigidTransform(), Sphere(R_OBJ), "ball", props(R_OBJ))
    tips = {}
    offsets = {"thumb": [R_OBJ + R_TIP - PEN, 0, 0], "index": [-(R_OBJ + R_TIP - PEN), 0, 0],
               "little": [0, 0.2, 0]}
    for name, off in offsets.items():
        body = plant.AddRigidBody(name, SpatialInertia(0.01, np.zeros(3),
                                                       UnitInertia.SolidSphere(R_TIP)))
        plant.RegisterCollisionGeometry(body, RigidTransform(), Sphere(R_TIP), name, props(R_TIP))
        plant.WeldFrames(plant.world_frame(), body.body_frame(), X_WO @ RigidTransform(off))
        tips[name] = body
    plant.Finalize()
    if swap:  # the thumb is "the object", the ball its only fingertip
        sys_ = ObjectContacts(plant, tips["thumb"], {"ball": ball}, pose_input=pose_input)
    else:
        sys_ = ObjectContacts(plant, "ball", tips, pose_input=pose_input)
    builder.AddSystem(sys_)
    builder.Connect(plant.get_contact_results_output_port(),
                    sys_.get_contact_results_input_port())
    if pose_input == "body_poses":
        builder.Connect(plant.get_body_poses_output_port(), sys_.get_pose_input_port())
    else:
        builder.ExportInput(sys_.get_pose_input_port(), "object_pose")
    diagram = builder.Build()
    context = diagram.CreateDefaultContext()
    plant.SetFreeBodyPose(plant.GetMyMutableContextFromRoot(context), ball, X_WO)
    if pose_input == "object_pose":
        diagram.get_input_port(0).FixValue(context, X_WO)
    return sys_, diagram, context


@pytest.mark.parametrize("pose_input", ["body_poses", "object_pose"])
def test_point_contacts_in_the_object_frame(pose_input):
    sys_, diagram, context = build(pose_input=pose_input)
    out = sys_.get_object_contacts_output_port().Eval(sys_.GetMyContextFromRoot(context))
    assert out.names == ("thumb", "index", "little")
    np.testing.assert_array_equal(out.in_contact, [True, True, False])
    for i, sign in ((0, 1.0), (1, -1.0)):
        # geometry: contact on the ball's surface at +-x of O within the penetration
        assert np.linalg.norm(out.p_OC[i] - [sign * R_OBJ, 0, 0]) <= PEN
        np.testing.assert_allclose(out.n_O[i], [-sign, 0, 0], atol=1e-9)  # inward
        f = out.f_O[i]
        assert f @ out.n_O[i] > 0  # the finger pushes
        np.testing.assert_allclose(np.cross(f, out.n_O[i]), 0, atol=1e-9 * np.linalg.norm(f))
        P, N = out.clouds[out.names[i]]
        assert P.shape == N.shape == (1, 3)
    np.testing.assert_allclose(out.f_O[0], -out.f_O[1], rtol=1e-9, atol=1e-12)  # symmetric
    # scored with the soft-finger model: the antipodal closure of the closed-form test
    g = out.grasp_contacts()
    assert g.names == ("thumb", "index")
    params = ContactParams(mu=0.5, gamma=0.002, characteristic_length=R_OBJ)
    q = grasp_quality(g.points, g.normals, params)
    assert q.force_closure
    assert q.value == pytest.approx(0.002 / R_OBJ, rel=1e-3)


def test_other_body_order_gives_the_other_sign():
    """Same contact seen from the thumb: inward normal into the thumb is +x of O."""
    sys_, diagram, context = build(swap=True)
    out = sys_.get_object_contacts_output_port().Eval(sys_.GetMyContextFromRoot(context))
    assert out.in_contact[0]
    # thumb frame is O translated by +x (same rotation): inward into the thumb is +x
    np.testing.assert_allclose(out.n_O[0], [1, 0, 0], atol=1e-9)
    assert np.linalg.norm(out.p_OC[0] - [-R_TIP, 0, 0]) <= PEN
    assert out.f_O[0] @ out.n_O[0] > 0


def test_hydroelastic_contacts_after_a_simulated_step():
    """With sampled output ports (the plant's default) the results exist after a step."""
    sys_, diagram, context = build(contact_model="hydroelastic_with_fallback", sampled=True)
    simulator = Simulator(diagram, context)
    simulator.AdvanceTo(2e-3)
    out = sys_.get_object_contacts_output_port().Eval(sys_.GetMyContextFromRoot(context))
    np.testing.assert_array_equal(out.in_contact, [True, True, False])
    for i, sign in ((0, 1.0), (1, -1.0)):
        assert np.linalg.norm(out.p_OC[i] - [sign * R_OBJ, 0, 0]) <= PEN
        np.testing.assert_allclose(out.n_O[i], [-sign, 0, 0], atol=1e-6)
        assert out.f_O[i] @ out.n_O[i] > 0


def test_no_contact_and_bad_arguments():
    sys_, diagram, context = build()
    plant = diagram.GetSubsystemByName(diagram.GetSystems()[0].get_name())
    with pytest.raises(ValueError, match="non-empty"):
        ObjectContacts(plant, "ball", {})
    with pytest.raises(ValueError, match="object body"):
        ObjectContacts(plant, "ball", {"x": "ball"})
    with pytest.raises(ValueError, match="given twice"):
        ObjectContacts(plant, "ball", {"a": "thumb", "b": "thumb"})
    with pytest.raises(TypeError, match="Body, BodyIndex or body name"):
        ObjectContacts(plant, "ball", {"a": 3.5})
    with pytest.raises(ValueError, match="pose_input"):
        ObjectContacts(plant, "ball", {"a": "thumb"}, pose_input="magic")
    out = sys_.get_object_contacts_output_port().Eval(sys_.GetMyContextFromRoot(context))
    out.in_contact[:] = False
    with pytest.raises(ValueError, match="at least one fingertip"):
        out.grasp_contacts()
