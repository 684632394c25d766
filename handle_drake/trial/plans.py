"""A grasp plan as a scenario: keyframes and a complete floating-wrist ``Scenario``.

:class:`~handle_drake.grasp.planning.GraspPlan` is numerics (grasp class + object ->
pre-shape, hand pose, stand-off); this module writes it as the station's input: the
open-loop keyframe script (reach from the stand-off, close, hold, lift), the whole
scenario, its YAML text, and the scenario's ``ObjectConfig`` of a planned object.
"""

from __future__ import annotations

import numpy as np
from pydrake.common.schema import Transform

from handle_drake.grasp.planning import GraspPlan
from handle_drake.scenario import (
    DumpScenario,
    FloatingWrist,
    HandConfig,
    Keyframe,
    ObjectConfig,
    Scenario,
    SimHandDriver,
    TableConfig,
    default_plant_config,
)

__all__ = ["plan_script", "plan_scenario", "plan_scenario_yaml", "object_config"]


def object_config(spec, **fields) -> ObjectConfig:
    """The scenario's ``ObjectConfig`` of a planned object (catalogue or mesh)."""
    if spec.kind == "mesh":
        return ObjectConfig(kind="mesh", file=spec.file, scale=spec.scale, mass=spec.mass,
                            density=spec.density, mu=spec.mu, **fields)
    return ObjectConfig(kind=spec.kind, size=spec.size, mu=spec.mu, **fields)


def plan_script(plan: GraspPlan, reach: float = 0.5, close: float = 0.5, hold: float = 0.3,
                lift: float = 0.7) -> list[Keyframe]:
    """Keyframes (durations in s): reach from the stand-off, close, hold, lift."""
    for name, v in (("reach", reach), ("close", close), ("hold", hold), ("lift", lift)):
        if not (np.isfinite(v) and v > 0):
            raise ValueError(f"{name} must be a positive duration (s), got {v}")
    t1 = reach
    t2 = t1 + 0.1
    t3 = t2 + close
    t4 = t3 + hold
    t5 = t4 + lift
    return [
        Keyframe(time=0.0, hand=plan.command_dict(plan.preshape_command),
                 wrist=plan.wrist(plan.X_WB_pregrasp)),
        Keyframe(time=t1, wrist=plan.wrist(plan.X_WB)),
        Keyframe(time=t2),
        Keyframe(time=t3, hand=plan.command_dict(plan.close_command)),
        Keyframe(time=t4),
        Keyframe(time=t5, wrist=plan.wrist(plan.lifted())),
    ]

def plan_scenario(plan: GraspPlan, settle: float = 0.5, world_object=None) -> Scenario:
    """A complete simulated ``Scenario`` (floating wrist, object, table,
    script). ``world_object`` (an ``ObjectConfig``) replaces the planned
    object: the plan then runs on the object that is really there."""
    script = plan_script(plan)
    spec = plan.object_spec
    return Scenario(
        hand=HandConfig(
            kind="shadow", coupling_ratio=plan.coupling_ratio,
            mount=FloatingWrist(X_WB=Transform(plan.X_WB_pregrasp)),
            initial_position=plan.command_dict(plan.preshape_command),
        ),
        object=world_object if world_object is not None else object_config(
            spec, X_WO=Transform(plan.X_WO), on_table=False),
        table=TableConfig(top_height=plan.table_height),
        plant_config=default_plant_config(time_step=0.001),
        driver=SimHandDriver(max_joint_velocity=4.0),
        simulation_duration=script[-1].time + settle,
        script=script,
    )


def plan_scenario_yaml(plan: GraspPlan) -> str:
    """The scenario as YAML text (``LoadScenario(data=...)`` or a file)."""
    return DumpScenario(plan_scenario(plan))
