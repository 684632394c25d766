"""The shipped scenarios from any folder (a wheel has no diagrams/ next to the user): by name,
by the README's diagrams/... path, listed and copied; a local file always wins."""

from __future__ import annotations

from pathlib import Path

import pytest

from handle_drake.base.models import diagrams_dir, shipped_path
from handle_drake.cli import build_parser
from handle_drake.cli import main as cli_main
from handle_drake.scenario import DumpScenario, LoadScenario


@pytest.fixture
def elsewhere(tmp_path, monkeypatch):
    """A working directory with no diagrams/ in it."""
    monkeypatch.chdir(tmp_path)
    return tmp_path


def test_a_shipped_scenario_loads_by_name_or_by_the_readme_path(elsewhere):
    shipped = diagrams_dir() / "shadow_sphere_grasp.yaml"
    for given in ("shadow_sphere_grasp", "shadow_sphere_grasp.yaml",
                  "diagrams/shadow_sphere_grasp.yaml"):
        assert shipped_path(given) == shipped
        assert DumpScenario(LoadScenario(filename=given)) == DumpScenario(
            LoadScenario(filename=shipped))
    # a shipped scenario's mesh, relative to the scenario, is found too
    bracket = LoadScenario(filename="barrett_mesh_bracket_grasp")
    assert Path(bracket.object.file) == diagrams_dir() / "meshes" / "l_bracket.obj"
    # anything else is left alone (its reader reports it)
    for other in ("nothing", "diagrams/nothing.yaml", "sub/shadow_sphere_grasp.yaml",
                  str(elsewhere / "shadow_sphere_grasp.yaml")):
        assert shipped_path(other) == Path(other)


def test_a_file_in_the_working_directory_wins(elsewhere):
    (elsewhere / "diagrams").mkdir()
    mine = elsewhere / "diagrams" / "shadow_sphere_grasp.yaml"
    text = (diagrams_dir() / "shadow_sphere_grasp.yaml").read_text()
    assert "kind: sphere" in text
    mine.write_text(text.replace("kind: sphere", "kind: cylinder"))
    assert shipped_path("diagrams/shadow_sphere_grasp.yaml") == Path(
        "diagrams/shadow_sphere_grasp.yaml")
    assert LoadScenario(filename="diagrams/shadow_sphere_grasp.yaml").object.kind == "cylinder"
    assert LoadScenario(filename="shadow_sphere_grasp").object.kind == "sphere"


def test_simulate_by_name_and_a_missing_file_says_where_the_shipped_ones_are(elsewhere, capsys):
    assert cli_main(["simulate", "shadow_sphere_grasp", "--duration", "0.02"]) == 0
    assert "simulated 0.02 s" in capsys.readouterr().out
    assert cli_main(["simulate", "diagrams/shadow_sphere_grasp.yaml", "--duration", "0.02"]) == 0
    capsys.readouterr()
    assert cli_main(["simulate", "diagrams/no_such.yaml"]) == 2
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1
    assert "scenario file not found: diagrams/no_such.yaml" in err
    assert "handle-drake diagrams list" in err and "handle-drake simulate NAME" in err


def test_diagrams_list_names_each_shipped_scenario(elsewhere, capsys):
    assert cli_main(["diagrams", "list"]) == 0
    names = [line.split()[0] for line in capsys.readouterr().out.splitlines()]
    assert names == sorted(p.stem for p in diagrams_dir().glob("*.yaml"))
    assert cli_main(["diagrams", "list", "--paths"]) == 0
    paths = capsys.readouterr().out.split()
    assert all(Path(p).is_file() for p in paths) and len(paths) == len(names)


def test_diagrams_copy_copies_scenarios_and_meshes_and_never_overwrites(elsewhere, capsys):
    assert cli_main(["diagrams", "copy", "mine"]) == 0
    source = diagrams_dir()
    for name in ("shadow_sphere_grasp.yaml", "meshes/part.stl", "meshes/l_bracket.obj"):
        assert (elsewhere / "mine" / name).read_bytes() == (source / name).read_bytes()
    # the copy runs as the shipped one (its mesh path is relative to the scenario)
    copied = LoadScenario(filename="mine/barrett_mesh_bracket_grasp.yaml")
    assert Path(copied.object.file) == (elsewhere / "mine/meshes/l_bracket.obj").resolve()
    (elsewhere / "mine" / "shadow_sphere_grasp.yaml").write_text("# edited\n")
    capsys.readouterr()
    assert cli_main(["diagrams", "copy", "mine"]) == 2
    assert "already there" in capsys.readouterr().err
    assert (elsewhere / "mine" / "shadow_sphere_grasp.yaml").read_text() == "# edited\n"


def test_the_readme_mesh_path_is_a_shipped_mesh(elsewhere):
    args = build_parser().parse_args(["grasp", "--class", "lateral", "--mesh",
                                      "diagrams/meshes/part.stl", "--mesh-scale", "0.001"])
    assert args.mesh == diagrams_dir() / "meshes" / "part.stl" and args.mesh.is_file()
