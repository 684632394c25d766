"""Depth cameras in the simulated station: Drake's ``RgbdSensor`` rendered by
``RenderEngineVtk``, the profile's depth model, and a world-frame point cloud.

Per camera ``<name>`` the station exports:

==========================  ====  =======================  ===========================
port                        dir   type                     units / frame
==========================  ====  =======================  ===========================
``<name>.rgb``              out   ``ImageRgba8U``          W x H
``<name>.depth``            out   ``ImageDepth32F``        m along the optical axis,
                                                           ``inf`` where invalid
``<name>.label``            out   ``ImageLabel16I``        render label per pixel
``<name>.point_cloud``      out   ``PointCloud``           m, world frame, valid pixels
``<name>.pose``             out   ``RigidTransform``       ``X_WC``
==========================  ====  =======================  ===========================
"""

from __future__ import annotations

import numpy as np
from pydrake.common.value import AbstractValue
from pydrake.geometry import MakeRenderEngineVtk, RenderEngineVtkParams
from pydrake.math import RigidTransform, RotationMatrix
from pydrake.perception import BaseField, DepthImageToPointCloud
from pydrake.systems.framework import LeafSystem
from pydrake.systems.sensors import CameraInfo, ImageDepth32F, PixelType, RgbdSensor

from handle_drake.base.hands import get_hand_spec
from handle_drake.devices.camera.config import ARM_PARENT_PREFIX, RENDERER, resolve_camera_config
from handle_drake.devices.camera.profiles import CameraProfile, apply_depth_model, get_profile

__all__ = ["AddCameras", "camera_info", "look_at", "DepthModel", "RENDERER"]


def camera_info(profile: CameraProfile) -> CameraInfo:
    return CameraInfo(width=profile.width, height=profile.height,
                      fov_y=np.radians(profile.fov_y_deg))


def look_at(eye, target) -> RigidTransform:
    """``X_WC`` of a camera at ``eye`` looking at ``target`` (Drake's camera
    frame: +z forward, +x right, +y down), image up as close to world +z as
    the view allows (world +y when looking straight down)."""
    eye = np.asarray(eye, dtype=float)
    z = np.asarray(target, dtype=float) - eye
    z /= np.linalg.norm(z)
    up = np.array([0.0, 0.0, 1.0])
    if abs(z @ up) > 0.999:
        up = np.array([0.0, 1.0, 0.0])
    x = np.cross(z, up)
    x /= np.linalg.norm(x)
    y = np.cross(z, x)
    return RigidTransform(RotationMatrix(np.column_stack([x, y, z])), eye)


class DepthModel(LeafSystem):
    """The profile's depth noise, quantisation and valid range applied to a
    rendered depth image. The noise of a frame is seeded by ``seed`` and the
    frame's time, so a run replays exactly."""

    def __init__(self, profile: CameraProfile, seed: int):
        super().__init__()
        self._profile = profile
        self._seed = int(seed)
        sample = AbstractValue.Make(ImageDepth32F(profile.width, profile.height))
        self._input = self.DeclareAbstractInputPort("depth_in", sample)
        self.DeclareAbstractOutputPort("depth", lambda: sample.Clone(), self._calc)

    def _calc(self, context, output):
        image = self._input.Eval(context)
        depth = np.asarray(image.data)[:, :, 0]
        rng = None
        if self._profile.noise_k > 0:
            nanoseconds = int(round(context.get_time() * 1e9))
            rng = np.random.default_rng([self._seed, nanoseconds])
        out = ImageDepth32F(self._profile.width, self._profile.height)
        np.asarray(out.mutable_data)[:, :, 0] = apply_depth_model(depth, self._profile, rng)
        output.set_value(out)


def AddCameras(builder, plant, scene_graph, scenario, hand_instance=None) -> None:
    """Adds the scenario's cameras to a station being built (after
    ``plant.Finalize()``) and exports their ports."""
    if not scenario.cameras:
        return
    if not scene_graph.HasRenderer(RENDERER):
        scene_graph.AddRenderer(RENDERER, MakeRenderEngineVtk(RenderEngineVtkParams()))
    for index, camera in enumerate(scenario.cameras):
        profile = get_profile(camera.profile)
        config = resolve_camera_config(camera, f"cameras[{index}]")
        # Drake's CameraConfig makes the render cameras (the profile's intrinsics,
        # the renderer's clipping and depth ranges; see devices.camera.config).
        color_camera, depth_camera = config.MakeCameras()
        info = depth_camera.core().intrinsics()
        X_PC = config.X_PB.GetDeterministicValue()
        if camera.parent == "world":
            parent_id = plant.GetBodyFrameIdOrThrow(plant.world_body().index())
            if camera.target:
                X_PC = look_at(X_PC.translation(), camera.target)
        elif camera.parent.startswith(ARM_PARENT_PREFIX):  # a link of the arm
            instance, _, link = camera.parent.rpartition("::")
            body = plant.GetBodyByName(link, plant.GetModelInstanceByName(instance))
            parent_id = plant.GetBodyFrameIdOrThrow(body.index())
        else:
            spec = get_hand_spec(scenario.hand.kind)
            base = plant.GetBodyByName(spec.base_body, hand_instance)
            parent_id = plant.GetBodyFrameIdOrThrow(base.index())
        sensor = builder.AddNamedSystem(
            f"camera_{camera.name}",
            RgbdSensor(parent_id, X_PC, color_camera, depth_camera))
        builder.Connect(scene_graph.get_query_output_port(), sensor.query_object_input_port())
        model = builder.AddNamedSystem(
            f"depth_model_{camera.name}",
            DepthModel(profile, seed=scenario.random_seed * 1000 + index))
        builder.Connect(sensor.depth_image_32F_output_port(), model.get_input_port())
        cloud = builder.AddNamedSystem(
            f"point_cloud_{camera.name}",
            DepthImageToPointCloud(info, PixelType.kDepth32F, 1.0, BaseField.kXYZs))
        builder.Connect(model.get_output_port(), cloud.depth_image_input_port())
        builder.Connect(sensor.body_pose_in_world_output_port(),
                        cloud.camera_pose_input_port())
        builder.ExportOutput(sensor.color_image_output_port(), f"{camera.name}.rgb")
        builder.ExportOutput(model.get_output_port(), f"{camera.name}.depth")
        builder.ExportOutput(sensor.label_image_output_port(), f"{camera.name}.label")
        builder.ExportOutput(cloud.point_cloud_output_port(), f"{camera.name}.point_cloud")
        builder.ExportOutput(sensor.body_pose_in_world_output_port(), f"{camera.name}.pose")
