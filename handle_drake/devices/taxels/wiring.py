"""What the station calls to add the taxel arrays, their drawing, their playback on the
hardware station and the object's pose estimator (``hand.taxels`` in a scenario)."""

from __future__ import annotations

from pydrake.math import RigidTransform

from handle_drake.devices.taxels.config import TaxelConfig
from handle_drake.devices.taxels.estimator import InHandPoseEstimator
from handle_drake.devices.taxels.pads import SHADOW_SKINS, shadow_pads, skin_rows
from handle_drake.devices.taxels.profiles import get_profile
from handle_drake.devices.taxels.sensor import (
    TaxelArray,
    TaxelMeshcat,
    TaxelPlayback,
    load_recording,
)

__all__ = ["AddTaxels", "AddTaxelMeshcat", "AddPoseEstimator", "AddTaxelPlayback",
           "taxel_cells", "TAXEL_PORT", "ESTIMATE_PORTS"]

TAXEL_PORT = "hand.taxels"
#: the estimator's station outputs and its optional camera input
ESTIMATE_PORTS = {"pose": "object.pose_estimated", "covariance": "object.pose_covariance",
                  "quality": "object.pose_quality"}
CAMERA_INPUT = "object.pose_detected"


def _profiles(config: TaxelConfig):
    """``(pad, palm, skin)`` profiles (palm, skin None when not asked for)."""
    pad = get_profile(config.profile)
    palm = get_profile(config.palm) if config.palm else None
    skin = get_profile(config.skin) if config.skin else None
    if config.rate_hz is not None:
        pad, palm, skin = (p.replace(rate_hz=config.rate_hz) if p is not None else None
                           for p in (pad, palm, skin))
    return pad, palm, skin


def taxel_cells(config: TaxelConfig) -> int:
    """Cells of ``hand.taxels``: five distal pads, the palm's and the skins, if any."""
    pad, palm, skin = _profiles(config)
    skins = sum(skin_rows(skin, length) * skin.cols for length in SHADOW_SKINS.values()) \
        if skin is not None else 0
    return 5 * pad.cells + (palm.cells if palm is not None else 0) + skins


def AddTaxels(builder, plant, scene_graph, hand, config: TaxelConfig, seed: int) -> TaxelArray:
    """The simulated taxel arrays (system ``taxels``), exported as ``hand.taxels``."""
    pad, palm, skin = _profiles(config)
    pads = shadow_pads(plant, hand, scene_graph.model_inspector(), pad, palm, skin)
    sensor = builder.AddNamedSystem("taxels", TaxelArray(plant, pads, noise=config.noise,
                                                         seed=seed))
    builder.Connect(plant.get_contact_results_output_port(),
                    sensor.get_contact_results_input_port())
    builder.Connect(plant.get_body_poses_output_port(), sensor.get_body_poses_input_port())
    builder.ExportOutput(sensor.GetOutputPort("taxels"), TAXEL_PORT)
    return sensor


def AddTaxelMeshcat(builder, plant, sensor: TaxelArray, meshcat, period: float):
    """Draws the taxel images on the pads in ``meshcat`` (system ``taxel_meshcat``)."""
    drawing = builder.AddNamedSystem("taxel_meshcat", TaxelMeshcat(meshcat, sensor.pads, period))
    builder.Connect(sensor.GetOutputPort("taxels"), drawing.GetInputPort("taxels"))
    builder.Connect(plant.get_body_poses_output_port(), drawing.GetInputPort("body_poses"))
    return drawing


def AddPoseEstimator(builder, sensor: TaxelArray, config: TaxelConfig, hand_kind: str,
                     coupling_ratio, spec, X_WO_prior: RigidTransform, hand_positions,
                     hand_pose=None, X_WB: RigidTransform | None = None,
                     roll_pitch=None, X_OS: RigidTransform | None = None):
    """The object's pose estimator (system ``object_pose_estimator``) fed by ports only:
    ``hand_positions`` (the measured joints), the sensor's taxels and ``hand_pose`` (the
    wrist's measured pose; None: the fixed ``X_WB``), and ``roll_pitch`` (the object's
    accelerometer's, its sensor at ``X_OS`` on the object; None: no accelerometer).
    Exports :data:`ESTIMATE_PORTS` and the camera input ``object.pose_detected``."""
    if (roll_pitch is None) != (X_OS is None):
        raise ValueError("AddPoseEstimator: roll_pitch and X_OS go together")
    estimator = builder.AddNamedSystem("object_pose_estimator", InHandPoseEstimator(
        hand_kind, coupling_ratio, sensor.pads, spec, X_WO_prior, X_WB=X_WB, X_OS=X_OS,
        rate_hz=config.estimator_rate_hz, prior_position_std=config.prior_position_std,
        prior_angle_std=config.prior_angle_std))
    if roll_pitch is not None:
        builder.Connect(roll_pitch, estimator.GetInputPort("roll_pitch"))
    builder.Connect(hand_positions, estimator.GetInputPort("hand_positions"))
    builder.Connect(sensor.GetOutputPort("taxels"), estimator.GetInputPort("taxels"))
    if hand_pose is not None:
        builder.Connect(hand_pose, estimator.GetInputPort("hand_pose"))
    for name, port in ESTIMATE_PORTS.items():
        builder.ExportOutput(estimator.GetOutputPort(name), port)
    builder.ExportInput(estimator.GetInputPort("camera_pose"), CAMERA_INPUT)
    return estimator


def AddTaxelPlayback(builder, config: TaxelConfig):
    """The hardware station's ``hand.taxels``: the recorded stream ``config.recording``."""
    times, frames = load_recording(config.recording, taxel_cells(config))
    playback = builder.AddNamedSystem("taxels", TaxelPlayback(times, frames))
    builder.ExportOutput(playback.GetOutputPort("taxels"), TAXEL_PORT)
    return playback
