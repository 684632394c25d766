"""Grasp planning as an application: the ``grasp``/``synergies`` commands
and executing a plan with tactile feedback in a station."""
