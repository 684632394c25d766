"""``handle-drake demo``: the Shadow hand grasps a sphere and lifts it.

The scenario is ``diagrams/shadow_sphere_grasp.yaml`` (shipped inside the
package as well). The demo reports whether the sphere held: it must rise with
the hand by at least :data:`REQUIRED_LIFT` and stay there until the end.
"""

from __future__ import annotations

import dataclasses as dc
from pathlib import Path

from handle_drake.base.models import diagrams_dir
from handle_drake.scenario import LoadScenario
from handle_drake.trial.simulate import REQUIRED_LIFT, RunResult, ScenarioRunner, held_through_lift

__all__ = ["DEMO_SCENARIO", "DemoReport", "run_demo"]

DEMO_SCENARIO = "shadow_sphere_grasp.yaml"


@dc.dataclass
class DemoReport:
    held: bool
    lift: float  # m, final height gain of the object
    quality: float  # BW metric of the final grasp (soft finger)
    force_closure: bool
    result: RunResult
    html: Path | None
    plot: Path | None

    def summary(self) -> str:
        verdict = "HELD" if self.held else "DROPPED"
        lines = [
            f"Shadow hand sphere grasp: {verdict} (object rose {self.lift * 100:.1f} cm; "
            f"required {REQUIRED_LIFT * 100:.0f} cm)",
            f"final grasp: BW metric {self.quality:+.3f}, "
            f"{'in force closure' if self.force_closure else 'not in force closure'}",
            f"simulated {self.result.sim_time:.1f} s in {self.result.wall_time:.1f} s "
            f"({self.result.realtime_factor:.1f}x real time)",
            "object height (m) over time:",
        ]
        step = max(1, len(self.result.times) // 10)
        for t, z in zip(self.result.times[::step], self.result.object_position[::step, 2],
                        strict=True):
            lines.append(f"  t = {t:4.2f} s   z = {z:.3f}")
        if self.plot:
            lines.append(f"plot: {self.plot}")
        if self.html:
            lines.append(f"replay: {self.html} (open in a browser)")
        return "\n".join(lines)


def run_demo(meshcat=None, html: str | Path | None = None,
             plot: str | Path | None = None) -> DemoReport:
    scenario = LoadScenario(filename=diagrams_dir() / DEMO_SCENARIO)
    # the station's systems are those of the outputs the demo logs (see MakeHandStation)
    runner = ScenarioRunner(scenario, meshcat, outputs=())
    result = runner.run(html=html if meshcat is not None else None)
    if plot is None and html is not None:
        plot = Path(html).with_suffix(".png")
    if plot is not None:
        _plot_height(result, Path(plot))
    quality, closure, _ = runner.grasp_quality()
    return DemoReport(
        held=held_through_lift(result),
        lift=result.object_lift(),
        quality=quality,
        force_closure=closure,
        result=result,
        html=Path(html) if (html is not None and meshcat is not None) else None,
        plot=Path(plot) if plot is not None else None,
    )


def _plot_height(result: RunResult, path: Path) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    path.parent.mkdir(parents=True, exist_ok=True)
    fig, axes = plt.subplots(2, 1, figsize=(7, 5), sharex=True)
    axes[0].plot(result.times, result.object_position[:, 2] * 100)
    axes[0].set_ylabel("object height (cm)")
    axes[1].plot(result.times, result.tactile)
    axes[1].set_ylabel("fingertip force (N)")
    axes[1].set_xlabel("time (s)")
    axes[1].legend(["FF", "MF", "RF", "LF", "TH"], ncol=5, fontsize=8)
    fig.tight_layout()
    fig.savefig(path, dpi=100)
    plt.close(fig)
