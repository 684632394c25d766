"""`pip install .` (not only -e) carries the models, scenarios and data."""

import subprocess
import sys
import zipfile
from pathlib import Path

from handle_drake.base.models import add_package, model_path, models_dir, package_url

ROOT = Path(__file__).resolve().parents[1]


def test_models_are_found_from_the_checkout():
    assert models_dir() == ROOT / "models"
    assert model_path("shadow_hand/shadow_hand_right.sdf").is_file()
    assert package_url("barrett_hand/bh8_280.sdf") == (
        "package://handle_drake_models/barrett_hand/bh8_280.sdf")


def test_package_url_of_a_missing_model_is_a_clear_error():
    import pytest

    with pytest.raises(FileNotFoundError, match="no model file"):
        package_url("shadow_hand/nope.sdf")


def test_parser_resolves_the_package():
    from pydrake.multibody.parsing import Parser
    from pydrake.multibody.plant import MultibodyPlant

    parser = Parser(MultibodyPlant(0.001))
    add_package(parser)
    add_package(parser)  # idempotent
    assert parser.package_map().GetPath("handle_drake_models") == str(models_dir())


def test_wheel_contains_models_scenarios_and_data(tmp_path):
    build = subprocess.run(
        [sys.executable, "-m", "pip", "wheel", "--no-deps", "-v",
         "-w", str(tmp_path), str(ROOT)],
        check=True, capture_output=True, text=True, timeout=300,
    )
    # Every data folder is a listed package: setuptools warns ("Package would be
    # ignored") for an importable folder that is not, and plans to drop its files.
    assert "absent from the `packages` configuration" not in build.stdout + build.stderr
    (wheel,) = tmp_path.glob("handle_drake-*.whl")
    names = set(zipfile.ZipFile(wheel).namelist())
    for required in ("handle_drake/_models/package.xml",
                     "handle_drake/_models/shadow_hand/shadow_hand_right.sdf",
                     "handle_drake/_models/barrett_hand/bh8_280.sdf",
                     "handle_drake/_diagrams/shadow_sphere_grasp.yaml",
                     "handle_drake/devices/can_hand/hand.dbc",
                     "handle_drake/devices/midi/icontrols_pro.yaml",
                     "handle_drake/_diagrams/midi_jog_pinch.yaml",
                     "handle_drake/_diagrams/meshes/part.stl",  # the README's mesh examples
                     "handle_drake/_diagrams/meshes/l_bracket.obj",
                     "handle_drake/grasp/data/synthetic_grasps.csv"):
        assert required in names, required
