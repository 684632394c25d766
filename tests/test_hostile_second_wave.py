"""Hostile input on the second-wave surfaces: inhand, instruments, midi, perceive,
mesh objects and --executor refuse bad input before any work, with one line
naming the option or field (exit 2, no traceback).

Each case was run by ``tools/hostile_probe.py second``; the ones here are
those refused without simulating (milliseconds each). ``{tmp}`` is the test's
folder, holding ``ok.yaml`` (a valid scenario), ``dir/``, ``fifo`` and the
meshes written by :func:`_files`.
"""

import os
import warnings

import numpy as np
import pytest
import trimesh

from handle_drake.cli import main
from handle_drake.geometry.objects.mesh import MeshObjectWarning
from handle_drake.scenario import LoadScenario, ScenarioError

CASES = [
    # (argv, words the one-line message must hold)
    ("inhand --workers 100000", ["workers", "100000"]),
    ("inhand --particles 1000000", ["--particles", "1..1000"]),  # the flag, since issue 46
    ("inhand --target-deg 1000", ["--target-deg", "360"]),
    ("inhand --db {tmp}/dir", ["--db", "directory"]),
    ("inhand --db {tmp}/ok.yaml", ["--db", "not an SQLite database"]),
    ("inhand --db {tmp}/ok.yaml/x.sqlite", ["--db", "is a file"]),
    ("inhand --plot {tmp}/dir", ["--plot", "directory"]),
    ("inhand --html {tmp}/dir", ["--html", "directory"]),
    ("inhand --trials 0", ["--trials"]),
    ("inhand --connect-timeout nan", ["--connect-timeout"]),
    ("inhand --executor ftp://x", ["--executor"]),
    ("instruments --seed -1", ["--seed", "2**32"]),
    ("instruments --json {tmp}/dir", ["--json", "directory"]),
    ("instruments --write-scenarios {tmp}/ok.yaml", ["--write-scenarios", "directory"]),
    ("midi jog --scenario {tmp}/fifo", ["scenario file", "FIFO"]),
    ("midi fader --override driver: 5", ["driver", "!SimHandDriver"]),
    ("midi fader --override midi_controller: null", ["midi_controller"]),
    ("midi control --mapping {tmp}/dir", ["MIDI mapping file", "directory"]),
    ("midi control --mapping {tmp}/mapping.yaml", ["controls", "a list"]),
    ("midi control --mapping {tmp}/mapping_dup.yaml", ["port_name", "duplicate"]),
    ("midi control --mapping {tmp}/garbage.stl", ["MIDI mapping file", "UTF-8"]),
    ("midi control --duration nan", ["--duration"]),
    ("midi control --hardware --duration 0.1", ["--hardware", "!CanHandDriver"]),
    ("midi write-scenarios {tmp}/ok.yaml", ["DIRECTORY", "directory"]),
    ("perceive {tmp}/ok.yaml", ["cameras", "no camera"]),
    ("perceive --frame {tmp}/fifo", ["frame file", "FIFO"]),
    ("perceive --frame {tmp}/frame.json", ["depth_png"]),
    ("perceive --frame {tmp}/garbage.stl", ["frame file", "UTF-8"]),
    ("grasp --class tripod --mesh {tmp}/dir", ["file", "directory"]),
    ("grasp --class tripod --mesh {tmp}/empty.stl", ["file", "no triangles"]),
    ("grasp --class tripod --mesh {tmp}/garbage.stl", ["file", "no triangles"]),
    ("grasp --class tripod --mesh {tmp}/line.obj", ["file", "degenerate"]),
    ("grasp --class tripod --mesh {tmp}/bad_index.obj", ["file", "cannot read mesh"]),
    ("grasp --class tripod --mesh {tmp}/km.stl", ["scale", "larger than a hand"]),
    ("grasp --class tripod --mesh {tmp}/box_mm.stl", ["scale", "millimetres", "0.001"]),
    ("grasp --class tripod --mesh {tmp}/box_mm.stl --mesh-scale 1e-300", ["scale", "smaller"]),
    ("grasp --class tripod --mesh {tmp}/box_mm.stl --mesh-scale 0.001 --mass 1e30",
     ["mass", "density"]),
    # once silently ignored: the mesh won over --object, the mesh options did nothing
    ("grasp --class tripod --mesh {tmp}/box_mm.stl --object sphere", ["--object", "--mesh"]),
    ("grasp --class tripod --mesh-scale 0.001 --size 0.05", ["--mesh-scale", "without --mesh"]),
    ("grasp --class tripod --mass 2 --size 0.05", ["--mass", "without --mesh"]),
    ("babble --mesh {tmp}/box_mm.stl --object mug", ["--object", "--mesh"]),
    ("babble --mesh-scale 0.001", ["--mesh-scale", "without --mesh"]),
    ("babble --mesh {tmp}/fifo", ["file", "FIFO"]),
    ("report --reduced --mesh {tmp}/km.stl", ["scale", "larger than a hand"]),
    ("babble --executor dask --workers 100000", ["workers", "per CPU core"]),
    ("babble --executor dask://127.0.0.1:99999", ["--executor"]),
]


def _files(tmp):
    (tmp / "ok.yaml").write_text("simulation_duration: 0.01\n")
    (tmp / "dir").mkdir()
    os.mkfifo(tmp / "fifo")
    trimesh.creation.box((40.0, 30.0, 60.0)).export(tmp / "box_mm.stl")  # millimetres
    trimesh.creation.box((1000.0, 1000.0, 1000.0)).export(tmp / "km.stl")
    (tmp / "empty.stl").write_bytes(b"")
    (tmp / "garbage.stl").write_bytes(np.random.default_rng(0).bytes(500))
    (tmp / "line.obj").write_text("v 0 0 0\nv 1 0 0\nv 2 0 0\nf 1 2 3\n")
    (tmp / "bad_index.obj").write_text("v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 99\n")
    (tmp / "frame.json").write_text('{"format": "handle_drake-depth-frame", "version": 1}')
    (tmp / "mapping.yaml").write_text("controls: 5\n")
    (tmp / "mapping_dup.yaml").write_text("port_name: a\nport_name: b\n")


@pytest.fixture(scope="module")
def folder(tmp_path_factory):
    tmp = tmp_path_factory.mktemp("hostile")
    _files(tmp)
    return tmp


@pytest.mark.parametrize("command,words", CASES, ids=[c[0][:50] for c in CASES])
def test_second_wave_cli_refuses_with_the_option_named(folder, capsys, command, words):
    # split on the first " --override " so the override's YAML stays one argument
    head, _, override = command.format(tmp=folder).partition(" --override ")
    argv = head.split() + (["--override", override] if override else [])
    try:
        code = main(argv)
    except SystemExit as exit_:  # argparse's own refusals
        code = exit_.code
    err = capsys.readouterr().err
    assert code == 2, err
    assert "Traceback" not in err and len(err) < 2000
    for word in words:
        assert word in err, (word, err)


@pytest.mark.parametrize("value", ["5", "5.5", "yes", "null"])
def test_a_number_boolean_or_null_in_a_text_field_is_refused_naming_it(value):
    with pytest.raises(ScenarioError, match=r"object\.file: expected a string"):
        LoadScenario(data=f"object: {{kind: mesh, file: {value}}}")
    # quoted, it is text: then the file is looked for
    with pytest.raises(ScenarioError, match="mesh file not found"):
        LoadScenario(data=f"object: {{kind: mesh, file: '{value}'}}")


def test_a_size_given_to_a_mesh_object_is_ignored_with_a_warning(folder):
    text = f"object: {{kind: mesh, file: {folder}/box_mm.stl, scale: 0.001, mass: 0.1}}"
    with warnings.catch_warnings():
        warnings.simplefilter("error", MeshObjectWarning)
        LoadScenario(data=text)  # no size: no warning
    with pytest.warns(MeshObjectWarning, match="object.size: ignored for a mesh"):
        LoadScenario(data=text[:-1] + ", size: 2}")


def test_simulate_says_when_the_object_ends_below_the_table(tmp_path, capsys):
    # Off the table's edge (the top spans |x| <= 0.4 m) the sphere falls: 0.4 s of free
    # fall is g t^2 / 2 = 0.78 m. Once only a height in the output said so.
    scenario = tmp_path / "s.yaml"
    scenario.write_text("object: {kind: sphere, size: 0.04, X_WO: {translation: [0.6, 0, 0]}}\n"
                        "simulation_duration: 0.4\n")
    assert main(["simulate", str(scenario)]) == 0
    out, err = capsys.readouterr()
    end = float(out.split("end ")[1].split(" m")[0])
    assert end == pytest.approx(0.02 - 9.81 * 0.4**2 / 2, abs=0.02)
    assert "warning: object.position" in err and "below the table top" in err
    scenario.write_text("object: {kind: sphere, size: 0.04}\nsimulation_duration: 0.1\n")
    assert main(["simulate", str(scenario)]) == 0
    assert "below the table" not in capsys.readouterr().err  # at rest on the top
