"""Robot arms that carry the hand (report section 2.2): the PA10-6C of the
Hamburg platform, its simulated joint driver and its kinematics.

- :mod:`handle_drake.arm.config`: the scenario's ``!Arm`` mount.
- :mod:`handle_drake.arm.model`: the arm's spec, :func:`AddArm`, the driver.
"""
