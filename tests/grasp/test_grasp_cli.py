"""The grasp area's sub-commands: synergies table/plot, grasp errors, committed scenarios."""

import argparse

import pytest

from handle_drake.demo import diagrams_dir, held_through_lift
from handle_drake.grasp import cli
from handle_drake.grasp.taxonomy import GRASP_CLASSES
from handle_drake.run import ScenarioRunner
from handle_drake.scenario import LoadScenario


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
