"""Instrumented objects: accelerometers in or on the grasped object (report section 2.4).

- :mod:`~handle_drake.geometry.objects.instrumented`: the JoyWarrior, Wiimote, Nunchuk and
  Sixaxis as catalogue objects with a named sensor frame (plain data).
- :mod:`~handle_drake.devices.accelerometer.profiles`: device profiles (range, bits, rate,
  noise, bias) and the counts <-> m/s^2 conversion.
- :mod:`~handle_drake.devices.accelerometer.sensor`: the device model on Drake's
  ``Accelerometer`` and :func:`AddObjectAccelerometer` for the station.
- :mod:`~handle_drake.devices.accelerometer.estimators`: roll/pitch with an at-rest flag, free
  fall and slip, as plain functions, as one per-sample update the device systems
  run in their own update (one event per sample), and as separate LeafSystems.
- :mod:`~handle_drake.devices.accelerometer.evdev_driver`: a real device (JoyWarrior as a Linux
  joystick) through ``evdev``, with the same estimators and ports.
- :mod:`~handle_drake.apps.figure8.experiments`: the Figure 8 experiments.

This package's ``__init__`` imports nothing heavy: ``handle_drake.geometry.objects`` reads
the catalogue at import.
"""
