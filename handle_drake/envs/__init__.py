"""Gymnasium environments of the in-hand tasks and the grasp trial.

``import handle_drake.envs`` registers them under the ``handle_drake`` namespace; without that
import, ``gymnasium.make("handle_drake.envs:handle_drake/ScrewCap-v0")`` imports the module
first (gymnasium 1.x has no plugin entry points). Needs the ``gym`` extra
(``pip install 'handle_drake[gym]'``).

=====================================  ===============================================
id                                     what
=====================================  ===============================================
``handle_drake/CylinderRotation-v0``   step level (:class:`~.inhand.InHandEnv`): joint
``handle_drake/StarRotation-v0``       targets in, joints, tactile and the object's sensor
``handle_drake/ScrewCap-v0``           out, one control period per step
``handle_drake/FingertipCylinder-v0``
``handle_drake/<Task>Gist-v0``         episode level (:class:`~.gist.GistEnv`): the gist's
                                       parameters in, one trial per step; vectorised over
                                       the trial executor with ``gymnasium.make_vec``; the
                                       four above and ``JogWheelGist-v0``
``handle_drake/Grasp-v0``              episode level: one grasp trial (the babbling
                                       trial's parameters) per step
=====================================  ===============================================
"""

from __future__ import annotations

import gymnasium

from handle_drake.envs.gist import GIST_TASKS, GistEnv, TrialVectorEnv, gist_trial
from handle_drake.envs.inhand import STEP_TASKS, InHandEnv, task_trial

__all__ = ["InHandEnv", "GistEnv", "TrialVectorEnv", "ENV_IDS", "STEP_IDS", "GIST_IDS",
           "register_envs", "task_trial", "gist_trial", "STEP_TASKS", "GIST_TASKS"]

NAMESPACE = "handle_drake"
_NAMES = {"cylinder_rotation": "CylinderRotation", "star_rotation": "StarRotation",
          "screw_cap": "ScrewCap", "fingertip_cylinder": "FingertipCylinder",
          "jog_wheel": "JogWheel"}
#: Step-level ids by task.
STEP_IDS = {task: f"{NAMESPACE}/{_NAMES[task]}-v0" for task in STEP_TASKS}
#: Episode-level (one trial per step) ids by task.
GIST_IDS = {**{task: f"{NAMESPACE}/{_NAMES[task]}Gist-v0" for task in (*STEP_TASKS,
                                                                       "jog_wheel")},
            "grasp": f"{NAMESPACE}/Grasp-v0"}
ENV_IDS = (*STEP_IDS.values(), *GIST_IDS.values())


def register_envs() -> None:
    """Registers every id (idempotent)."""
    for task, env_id in STEP_IDS.items():
        if env_id not in gymnasium.registry:
            gymnasium.register(env_id, entry_point=InHandEnv, kwargs={"task": task})
    for task, env_id in GIST_IDS.items():
        if env_id not in gymnasium.registry:
            gymnasium.register(env_id, entry_point=GistEnv, kwargs={"task": task},
                               vector_entry_point=TrialVectorEnv)


register_envs()
