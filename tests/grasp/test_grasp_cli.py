"""The grasp area's sub-commands: synergies table/plot, grasp errors, committed scenarios."""

import argparse

import pytest

from handle_drake.apps.planning import cli
from handle_drake.base.models import diagrams_dir
from handle_drake.grasp.taxonomy import GRASP_CLASSES
from handle_drake.scenario import LoadScenario
from handle_drake.trial.simulate import ScenarioRunner, held_through_lift


def _parse(argv):
    parser = argparse.ArgumentParser()
    cli.register(parser.add_subparsers(dest="command", required=True))
    return parser.parse_args(argv)


def test_synergies_prints_the_error_table_and_saves_a_plot(tmp_path, capsys):
    plot = tmp_path / "err.png"
    args = _parse(["synergies", "--k-max", "4", "--plot", str(plot)])
    assert args.func(args) == 0
    out = capsys.readouterr().out
    assert "| k | explained variance |" in out and "| 4 |" in out
    assert plot.stat().st_size > 1000


def test_grasp_rejects_bad_input_with_clear_errors():
    args = _parse(["grasp", "--class", "power", "--object", "sphere", "--size", "0.04"])
    with pytest.raises(ValueError, match="unknown grasp class"):
        args.func(args)
    args = _parse(["grasp", "--class", "tripod", "--object", "sphere", "--size", "0.2"])
    with pytest.raises(ValueError, match="too large"):
        args.func(args)
    args = _parse(["synergies", "/nonexistent.csv"])
    with pytest.raises(FileNotFoundError):
        args.func(args)


def test_every_class_has_a_committed_scenario_that_loads():
    for info in GRASP_CLASSES.values():
        scenario = LoadScenario(filename=diagrams_dir() / f"grasp_{info.name}.yaml")
        assert scenario.script and scenario.object.kind in ("sphere", "cuboid", "cylinder")


def test_committed_parallel_extension_scenario_holds():
    scenario = LoadScenario(filename=diagrams_dir() / "grasp_parallel_extension.yaml")
    assert held_through_lift(ScenarioRunner(scenario).run())


def test_grasp_with_a_pose_error_and_recentring(capsys):
    """`handle-drake grasp --pose-error DX DY --recentre`: the tip pinch of a 22.5 mm
    ball 10.6 mm from where the plan thinks; the re-centred reactive close holds it
    (open loop drops it: tests/grasp/test_execution.py)."""
    args = _parse(["grasp", "--class", "tip_pinch", "--object", "sphere", "--size", "0.0225",
                   "--pose-error", "0.007", "0.008", "--recentre"])
    assert args.func(args) == 0
    out = capsys.readouterr().out
    assert "re-centring on the first touch" in out and "+7.0, +8.0 mm" in out
    assert "HELD" in out


def test_pose_error_and_recentring_refuse_what_they_cannot_do():
    for argv, message in (
            (["--open-loop", "--recentre"], "does not apply to --open-loop"),
            (["--pose-error", "0.2", "0"], "at most 0.1 m"),
            (["--pose-error", "nan", "0"], "two finite offsets"),
            (["--pose-error", "0.01", "0", "--perceived"], "give one or the other")):
        args = _parse(["grasp", "--class", "tripod", "--object", "sphere", "--size", "0.04",
                       *argv])
        with pytest.raises(ValueError, match=message):
            args.func(args)
