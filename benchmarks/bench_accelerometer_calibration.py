"""A resting accelerometer, per device profile: raw against six-position calibrated.

Each noisy profile (JoyWarrior, Wiimote, Nunchuk, Sixaxis), seeds 0-19, three
rest orientations (level; roll 25, pitch -15; roll -70, pitch 50 deg), the
hand's command still, 1.5 s: the device system as the station builds it
(``DeviceAccelerometer`` with its estimators), fed the exact specific force of
a body at rest. Three set-ups:

- ``raw, default thresholds``: no calibration, :class:`EstimatorParams`
  defaults (before issue 30);
- ``raw, device thresholds``: ``calibrated: false`` in a scenario (thresholds
  widened to the device's bias and noise);
- ``calibrated``: the default (six-position calibration, device thresholds).

Reported per set-up: roll/pitch error at rest (deg, median and max over the
samples after the settle time), the share of those samples not flagged at rest,
the share flagged as slip, and the calibration's residual bias (mg, max over
seeds, against its stated bound).

Usage: ``python benchmarks/bench_accelerometer_calibration.py [--seeds N]``
"""

from __future__ import annotations

import argparse
from pathlib import Path

from handle_drake.base.blas import pin_blas  # noqa: E402 - light: loads neither numpy nor Drake

pin_blas()

import numpy as np  # noqa: E402
from pydrake.math import RollPitchYaw  # noqa: E402
from pydrake.systems.analysis import Simulator  # noqa: E402
from pydrake.systems.framework import DiagramBuilder  # noqa: E402
from pydrake.systems.primitives import ConstantVectorSource, VectorLogSink  # noqa: E402

from handle_drake.base.results import ResultsRun, add_page_arguments  # noqa: E402
from handle_drake.devices.accelerometer.calibration import (  # noqa: E402
    calibrate_device,
    device_estimator_params,
    residual_bias,
)
from handle_drake.devices.accelerometer.estimators import EstimatorParams, true_roll_pitch  # noqa: E402
from handle_drake.devices.accelerometer.profiles import (  # noqa: E402
    PROFILES,
    STANDARD_GRAVITY,
    device_bias,
)
from handle_drake.devices.accelerometer.sensor import DeviceAccelerometer  # noqa: E402

ORIENTATIONS = [(0.0, 0.0, 0.0), (25.0, -15.0, 40.0), (-70.0, 50.0, -120.0)]
SETUPS = ("raw, default thresholds", "raw, device thresholds", "calibrated")


def rest_run(profile, seed, rpy_deg, params, calibration, duration=1.5):
    R_WS = RollPitchYaw(np.radians(rpy_deg)).ToRotationMatrix()
    builder = DiagramBuilder()
    source = builder.AddSystem(ConstantVectorSource(R_WS.inverse() @ [0, 0, STANDARD_GRAVITY]))
    command = builder.AddSystem(ConstantVectorSource(np.zeros(2)))
    device = builder.AddSystem(DeviceAccelerometer(profile, seed, estimators=params,
                                                   command_size=2, calibration=calibration))
    builder.Connect(source.get_output_port(), device.GetInputPort("specific_force"))
    builder.Connect(command.get_output_port(), device.GetInputPort("command"))
    logs = {}
    for name in ("at_rest", "slip", "roll_pitch"):
        port = device.GetOutputPort(name)
        logs[name] = builder.AddSystem(VectorLogSink(port.size(), profile.period))
        builder.Connect(port, logs[name].get_input_port())
    simulator = Simulator(builder.Build())
    simulator.AdvanceTo(duration)
    context = simulator.get_context()
    t = logs["slip"].FindLog(context).sample_times()
    after = t > EstimatorParams().settle_time
    data = {n: log.FindLog(context).data()[:, after] for n, log in logs.items()}
    error = np.degrees(np.abs(data["roll_pitch"].T - true_roll_pitch(R_WS))).max(axis=1)
    return error, data["at_rest"][0] < 0.5, data["slip"][0] > 0.5


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--seeds", type=int, default=20)
    parser.add_argument("--out", type=Path, default=Path(__file__).parent / "results"
                        / "accelerometer_calibration.json")
    add_page_arguments(parser, "accelerometer_calibration", published={"seeds": 20})
    args = parser.parse_args()
    run = ResultsRun("Accelerometer at rest: roll/pitch error and flags per device and set-up",
                     args)
    rows = []
    for name, profile in PROFILES.items():
        if profile.bias_std_g == 0:
            continue
        residual = max(np.linalg.norm(np.array(calibrate_device(profile, s).offset)
                                      - device_bias(profile, s)) for s in range(args.seeds))
        for setup in SETUPS:
            calibrated = setup == "calibrated"
            params = (EstimatorParams() if setup.endswith("default thresholds")
                      else device_estimator_params(profile, calibrated))
            errors, not_rest, slip = [], [], []
            for seed in range(args.seeds):
                calibration = calibrate_device(profile, seed) if calibrated else None
                for rpy in ORIENTATIONS:
                    e, r, s = rest_run(profile, seed, rpy, params, calibration)
                    errors.append(e)
                    not_rest.append(r)
                    slip.append(s)
            errors, not_rest, slip = map(np.concatenate, (errors, not_rest, slip))
            rows.append({
                "device": name, "setup": setup,
                "rp_error_median_deg": float(np.median(errors)),
                "rp_error_max_deg": float(errors.max()),
                "not_at_rest_share": float(not_rest.mean()),
                "slip_share": float(slip.mean()),
                "rest_norm_tol_g": params.rest_norm_tol, "slip_norm_tol_g": params.slip_norm_tol,
                "residual_bias_mg": 1e3 * residual / STANDARD_GRAVITY,
                "residual_bound_mg": 1e3 * residual_bias(profile, True),
            })
    head = (f"{'device':16s} {'set-up':24s} {'roll/pitch err deg':>19s} {'not at rest':>11s} "
            f"{'slip':>7s} {'rest/slip norm tol g':>21s}")
    print(head)
    print("-" * len(head))
    for r in rows:
        print(f"{r['device']:16s} {r['setup']:24s} {r['rp_error_median_deg']:8.2f} / "
              f"{r['rp_error_max_deg']:6.2f}   {100 * r['not_at_rest_share']:9.2f} % "
              f"{100 * r['slip_share']:5.2f} % {r['rest_norm_tol_g']:9.3f} / "
              f"{r['slip_norm_tol_g']:.3f}")
    print()
    for r in rows[::len(SETUPS)]:
        print(f"{r['device']:16s} calibration residual bias (length, max over seeds) "
              f"{r['residual_bias_mg']:.2f} mg, bound {r['residual_bound_mg']:.2f} mg")
    run.finish(rows, {"seeds": args.seeds, "orientations_deg": ORIENTATIONS, "rows": rows},
               args.out)
    print(f"results: {args.out}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
