"""The grasp experiments of report section 4.3, built on the engine in :mod:`handle_drake.learning`.

:mod:`.grasp_trial` (one simulated grasp: parameters -> metric),
:mod:`.babbling` (run specs, batches of logged runs, dense-grid ground truth),
:mod:`.report` (``handle-drake report``), :mod:`.plots` (a run's figure and
the report's panels) and :mod:`.cli` (the ``babble`` and ``report``
sub-commands). Import from the modules; this package re-exports nothing so
that ``import handle_drake.apps.babbling`` stays cheap.
"""
