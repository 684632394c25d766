"""Perception in clutter, issue 49 item 6: the held-out cases (a tall wine
glass near the camera gave 3 detections alone on the table; a box and a ball
20 mm apart gave 3) and objects 15-20 mm apart kept apart. Each scene is
rendered through the tabletop Kinect (noise on); the truth (the scene's
objects) only scores the detections."""

import itertools
import math

import numpy as np
import pytest

from handle_drake.apps.perception.scenes import (
    CLUTTER_DEV_SEEDS,
    CLUTTER_FINAL_SEEDS,
    CLUTTER_FRESH_SEEDS,
    CLUTTER_HELD_OUT_SEEDS,
    SceneObject,
    TabletopScene,
    clutter_scene,
    footprint_gap,
    match_detections,
)
from handle_drake.geometry.detect import detect


def _detect(objects, seed=0):
    detections = detect(TabletopScene(objects, seed=seed).frame(0.0))
    return detections, match_detections(detections, objects)


def _described(detections):
    return [(d.kind, np.round(d.position, 3).tolist(), np.round(d.extent, 3).tolist())
            for d in detections]


@pytest.mark.parametrize("size, xy", [(0.08, (-0.15, 0.0)), (0.08, (-0.15, 0.1)),
                                      (0.10, (-0.15, 0.0)), (0.10, (-0.15, 0.1))])
def test_a_tall_wine_glass_near_the_camera_is_one_object(size, xy):
    """Was 3 (0.08) or 2 (0.10) detections: the camera, 45 deg down, sees the
    bowl's near wall, the inside of its far wall (over the rim) and the foot
    with the stem as three clusters that do not touch."""
    glass = SceneObject("wine_glass", size, xy)
    detections, score = _detect([glass])
    assert len(detections) == 1, _described(detections)
    (found,) = score["objects"]
    # The 100 mm glass's near wall is nearer than the Kinect's 0.8 m minimum
    # range (invalid pixels): its centre comes from the foot and the far
    # wall's inside, 10.3-10.4 mm off (measured); the 80 mm glass's within 5.
    assert found["kind_ok"] and found["xy_mm"] < (5 if size < 0.09 else 12), found


BOX = SceneObject("cuboid", 0.05, (0.02, 0.03), 0.0)  # 50 x 30 x 75 mm, faces on x and y


def _ball_beside_box(diameter, direction_deg, gap):
    """A ball ``gap`` (m) from BOX's footprint, in the direction (deg, world:
    180 is towards the camera) from the box's centre."""
    u = np.array([math.cos(math.radians(direction_deg)), math.sin(math.radians(direction_deg))])
    lo, hi = 0.0, 0.3
    for _ in range(50):  # bisection on the outline gap (footprint_gap: sampled outlines)
        mid = (lo + hi) / 2
        ball = SceneObject("sphere", diameter, tuple(np.add(BOX.xy, mid * u)))
        lo, hi = (mid, hi) if footprint_gap(BOX, ball) < gap else (lo, mid)
    return SceneObject("sphere", diameter, tuple(np.add(BOX.xy, hi * u)))


@pytest.mark.parametrize("gap, diameter, direction", [
    *itertools.product([0.015, 0.020], [0.03], [90, 135, 180, 225, 270]),
    *itertools.product([0.015], [0.06], [90, 180, 270])])
def test_a_box_and_a_ball_15_to_20_mm_apart_are_two_objects(gap, diameter, direction):
    """Was 3 detections (every one of these): the box's side face, seen
    edge-on from the camera, made a strip of 10 points apart from the box."""
    ball = _ball_beside_box(diameter, direction, gap)
    assert abs(footprint_gap(BOX, ball) - gap) < 0.001
    detections, score = _detect([BOX, ball])
    assert len(detections) == 2 and score["phantoms"] == 0, _described(detections)
    for found in score["objects"]:
        assert found["kind_ok"] and found["xy_mm"] < 5, found


def test_clutter_scenes_stand_15_to_20_mm_apart():
    """Every object of a clutter scene is 15-20 mm (outline to outline) from
    its nearest neighbour and at least 15 mm from every other; seeded."""
    assert clutter_scene(3) == clutter_scene(3) and clutter_scene(3) != clutter_scene(4)
    blocks = [set(CLUTTER_DEV_SEEDS), set(CLUTTER_HELD_OUT_SEEDS), set(CLUTTER_FRESH_SEEDS),
              set(CLUTTER_FINAL_SEEDS)]
    assert all(not a & b for a, b in itertools.combinations(blocks, 2))
    for seed in CLUTTER_DEV_SEEDS[:10]:
        objects = clutter_scene(seed)
        assert 2 <= len(objects) <= 5
        for a in objects:
            gaps = [footprint_gap(a, b) for b in objects if b is not a]
            assert 0.0145 <= min(gaps) <= 0.0205, (seed, a, gaps)
    with pytest.raises(ValueError, match="gap"):
        clutter_scene(0, gap=(0.02, 0.01))
    with pytest.raises(ValueError, match="count"):
        clutter_scene(0, count=0)


def test_footprint_gap_of_two_boxes_is_the_distance_between_their_faces():
    a = SceneObject("cuboid", 0.05, (0.0, 0.0))  # x in [-0.025, 0.025]
    b = SceneObject("cuboid", 0.05, (0.07, 0.0))  # x in [0.045, 0.095]
    assert footprint_gap(a, b) == pytest.approx(0.020, abs=1e-6)
    assert footprint_gap(a, SceneObject("cuboid", 0.05, (0.01, 0.0))) == 0.0


@pytest.mark.parametrize("seed", [0, 1, 3, 7])
def test_clutter_scenes_every_object_apart_and_its_kind(seed):
    """Development seeds (never the held-out block): one detection per
    object, within 1 cm, of its kind."""
    objects = clutter_scene(seed)
    detections, score = _detect(objects, seed=seed)
    assert score["phantoms"] == 0 and len(detections) == len(objects), _described(detections)
    for found in score["objects"]:
        assert found["xy_mm"] is not None and found["xy_mm"] <= 10, found
        assert found["kind_ok"], found


def test_a_box_seen_in_pieces_behind_a_wine_glass_is_one_object():
    """A box behind a glass, seen only beside the stem and under the bowl
    (5 % of it in view: 4 pieces of 10-21 points, 15-50 mm apart): one
    detection where the box is, no phantom. The pieces join because the
    camera cannot see between them (a nearer surface hides it): this needs
    the camera's position, which a depth frame carries; from bare points the
    pieces stay apart."""
    from handle_drake.geometry.detect import detect_objects

    glass = SceneObject("wine_glass", 0.0798, (0.013, 0.083), 1.8)
    box = SceneObject("rotated_cuboid", 0.0688, (0.094, 0.091), 1.09)
    frame = TabletopScene([glass, box]).frame(0.0)
    detections = detect(frame)
    score = match_detections(detections, [glass, box])
    assert len(detections) == 2 and score["phantoms"] == 0, _described(detections)
    found_glass, found_box = score["objects"]
    assert found_glass["kind_ok"] and found_glass["xy_mm"] < 5, found_glass
    assert found_box["xy_mm"] < 10, found_box  # its kind: too little in view to tell
    assert len(detect_objects(frame.points())[1]) > 2  # without the camera: pieces
    with pytest.raises(ValueError, match="camera"):
        detect_objects(frame.points(), camera=[0.0, 1.0])


@pytest.mark.parametrize("size", [0.05, 0.06])
def test_a_tall_cylinder_whose_near_top_is_out_of_range_is_one_object(size):
    """Was 2 detections: the top's near edge is nearer to the camera than the
    Kinect's 0.8 m minimum range, so the camera sees the far part of the top
    and the side below the cut apart, with no return between them."""
    from handle_drake.devices.camera.profiles import get_profile

    cylinder = SceneObject("cylinder", size, (-0.19, -0.09), 2.4)
    scene = TabletopScene([cylinder])
    frame = scene.frame(0.0)
    # The scene is what the test says: the top's nearest point out of range.
    camera = frame.X_WC[:3, 3]
    near_top = np.array([-0.19 - size / 2 * 0.9, -0.09, 2 * size])
    axis = frame.X_WC[:3, 2]
    assert (near_top - camera) @ axis < get_profile("kinect_v1").min_depth
    detections = detect(frame)
    score = match_detections(detections, [cylinder])
    assert len(detections) == 1, _described(detections)
    (found,) = score["objects"]
    assert found["kind_ok"] and found["xy_mm"] < 5, found


@pytest.mark.parametrize("kind, xy, yaw", [("cuboid", (-0.17, 0.0), 0.5),
                                           ("rotated_cuboid", (-0.18, 0.0), 0.0)])
def test_an_80_mm_box_near_the_camera_is_one_box(kind, xy, yaw):
    """Was a cylinder (and, the rotated one, 2 detections): the near part of
    the top is beyond the Kinect's range, so the top's outline is cut and
    fills less than a box's; the box fits 4x better than the cylinder."""
    box = SceneObject(kind, 0.08, xy, yaw)
    detections, score = _detect([box])
    assert len(detections) == 1, _described(detections)
    (found,) = score["objects"]
    assert found["kind_detected"] == "box" and found["xy_mm"] < 5, found
