"""Several objects per scenario and the toy-sorting box."""

import numpy as np
import pytest
from pydrake.systems.analysis import Simulator

from handle_drake.geometry.objects import ObjectSpec, resting_height
from handle_drake.scenario import LoadScenario, ScenarioError
from handle_drake.scene.config import Hole, hole_centres, hole_polygon, in_box, scene_objects
from handle_drake.scene.plant import lid_pieces
from handle_drake.station import MakeHandStation

HAND_AWAY = ("hand: {kind: barrett, mount: !FixedMount "
             "{X_WB: {translation: [-0.3, 0.35, 0.6]}}}\n")


def _area(polygon):
    """Shoelace area of a polygon (n, 2) in order."""
    x, y = polygon[:, 0], polygon[:, 1]
    return 0.5 * abs(np.dot(x, np.roll(y, -1)) - np.dot(y, np.roll(x, -1)))


def _hull_area(points):
    from scipy.spatial import ConvexHull

    return ConvexHull(points).volume  # 2-D: the area


@pytest.mark.parametrize("kind", ["cylinder", "cuboid", "star_prism", "sphere", "mug",
                                  "wine_glass", "rotated_cuboid"])
def test_lid_pieces_tile_the_cell_around_the_hole(kind):
    polygon = hole_polygon(Hole(kind))
    # The toy's cell, or larger for a hole that reaches further (the mug's handle)
    half = np.maximum([0.0625, 0.09], np.max(np.abs(polygon), axis=0) + 0.01)
    pieces = lid_pieces(polygon, half)
    assert len(pieces) == len(polygon)
    total = sum(_hull_area(p) for p in pieces)
    assert total == pytest.approx(4 * half[0] * half[1] - _area(polygon), rel=1e-9)
    # No piece covers the hole: the hole's centre and its vertices' midpoints toward
    # the centre are outside every piece.
    from scipy.spatial import Delaunay

    probes = np.vstack([[0, 0], 0.9 * polygon])
    for p in pieces:
        assert not np.any(Delaunay(p).find_simplex(probes) >= 0)


def test_hole_matches_its_object_with_the_clearance():
    circle = hole_polygon(Hole("cylinder", 0.05, clearance=0.01))
    # The polygon is circumscribed about the circle of the diameter plus clearance.
    assert np.min(np.linalg.norm(circle, axis=1)) >= 0.035 - 1e-12
    square = hole_polygon(Hole("cuboid", 0.06, clearance=0.01))
    np.testing.assert_allclose(np.ptp(square, axis=0), [0.06 + 0.02, 0.06 + 0.02])
    star = hole_polygon(Hole("star_prism", 0.08, clearance=0.01))
    np.testing.assert_allclose(np.max(np.linalg.norm(star, axis=1)), 0.05)
    # A wine glass's hole: its bowl's widest circle (8 cm) plus the clearance.
    glass = hole_polygon(Hole("wine_glass", 0.08, clearance=0.01))
    assert np.min(np.linalg.norm(glass, axis=1)) >= 0.05 - 1e-12
    # A mug's: the circle about its cup's axis through its handle's end (8 cm cup, the
    # handle reaching 2.4 cm out), plus the clearance: it passes at any yaw.
    mug = hole_polygon(Hole("mug", 0.08, clearance=0.01))
    assert np.min(np.linalg.norm(mug, axis=1)) >= 0.04 + 0.024 + 0.01 - 1e-9
    # A user's mesh's: the convex hull of its footprint (a hexagonal prism, 3.2 cm to a
    # corner), every edge moved out by the clearance, counter-clockwise.
    from handle_drake.base.models import diagrams_dir

    hexagon = hole_polygon(Hole("mesh", file=str(diagrams_dir() / "meshes" / "hex_prism.obj"),
                                clearance=0.01))
    edges = np.roll(hexagon, -1, axis=0) - hexagon
    outward = np.column_stack([edges[:, 1], -edges[:, 0]])
    outward /= np.linalg.norm(outward, axis=1, keepdims=True)
    distance = np.einsum("ij,ij->i", outward, hexagon)
    np.testing.assert_allclose(distance, 0.032 * np.cos(np.pi / 6) + 0.01, atol=1e-6)


def _scene(extra=""):
    return LoadScenario(data=HAND_AWAY + """
object: {kind: cylinder, size: 0.05, X_WO: {translation: [0.0, -0.15, 0]}}
objects:
  - {kind: cuboid, size: 0.06, X_WO: {translation: [0.15, -0.15, 0]}}
  - {kind: sphere, size: 0.06, X_WO: {translation: [-0.15, -0.15, 0]}}
sorting_box: {X_WB: {translation: [0, 0.2, 0]}}
simulation_duration: 0.3
""" + extra)


def test_several_objects_rest_where_placed_with_their_ports():
    scenario = _scene()
    names = [name for name, _ in scene_objects(scenario)]
    assert names == ["object", "object_1", "object_2"]
    station = MakeHandStation(scenario)
    simulator = Simulator(station)
    simulator.AdvanceTo(0.3)
    context = simulator.get_context()
    for name, o in scene_objects(scenario):
        p = station.GetOutputPort(f"{name}.position").Eval(context)
        expected = np.array(o.X_WO.translation, dtype=float)
        expected[2] = resting_height(ObjectSpec(kind=o.kind, size=o.size))
        np.testing.assert_allclose(p, expected, atol=2e-3)


def test_a_single_object_scenario_is_unchanged():
    scenario = LoadScenario(data=HAND_AWAY + "object: {kind: sphere, size: 0.06}\n")
    assert scenario.objects == [] and scenario.sorting_box is None
    assert [n for n, _ in scene_objects(scenario)] == ["object"]


@pytest.mark.parametrize("extra, message", [
    ("objects: [{kind: cuboid}, {kind: teapot, X_WO: {translation: [0.3, 0.3, 0]}}]",
     "objects[1].kind: unknown object 'teapot'"),
    ("objects: [{kind: sphere, size: -1}]", "objects[0].size must be"),
    ("objects: [{kind: sphere, size: 0.06, X_WO: {translation: [0.01, 0, 0]}}]",
     "object_1: starts inside object"),
    ("sorting_box: {X_WB: {translation: [0, 0, 0]}}", "object: starts on or in the sorting box"),
    ("sorting_box: {size: [0.2, 0.18, 0.14], X_WB: {translation: [0, 0.3, 0]}}",
     "does not fit its"),
    ("sorting_box: {holes: [{kind: joywarrior}], X_WB: {translation: [0, 0.3, 0]}}",
     "sorting_box.holes[0].kind: no hole shape for 'joywarrior'"),
    ("sorting_box: {holes: [{kind: mesh}], X_WB: {translation: [0, 0.3, 0]}}",
     "sorting_box.holes[0].file: a mesh hole needs"),
    ("sorting_box: {rows: 3, holes: [{kind: mug}, {kind: sphere}], "
     "X_WB: {translation: [0, 0.3, 0]}}", "sorting_box.rows: expected an integer from 1"),
])
def test_bad_scenes_are_refused_with_the_field_named(extra, message):
    with pytest.raises(ScenarioError) as error:
        LoadScenario(data=HAND_AWAY + "object: {kind: sphere, size: 0.06}\n" + extra)
    assert message in str(error.value)


@pytest.mark.parametrize("size, inside", [(0.06, True), (0.10, False)])
def test_a_ball_falls_through_its_hole_only_if_it_fits(size, inside):
    """Physics: a 6 cm ball dropped over the sphere hole (8.4 cm) ends in the box;
    a 10 cm ball stays on the lid."""
    box = _scene().sorting_box
    centre = hole_centres(LoadScenario(data=HAND_AWAY + "object: null\nsorting_box: "
                                       "{X_WB: {translation: [0, 0.2, 0]}}"))["sphere"]
    scenario = LoadScenario(data=HAND_AWAY + f"""
object: {{kind: sphere, size: {size}, on_table: false,
          X_WO: {{translation: [{centre[0]}, {centre[1]}, {centre[2] + 0.08}]}}}}
sorting_box: {{X_WB: {{translation: [0, 0.2, 0]}}}}
""")
    assert scenario.sorting_box.size == box.size
    station = MakeHandStation(scenario)
    simulator = Simulator(station)
    simulator.AdvanceTo(0.8)
    p = station.GetOutputPort("object.position").Eval(simulator.get_context())
    assert in_box(scenario, p) is inside
    if not inside:
        assert p[2] > centre[2]  # resting in the hole's rim, above the lid's underside
