"""Property-based fuzzing (hypothesis) of issue 31's input surfaces.

Properties, for any input the strategies build:

- a ``dask://`` address served by a hostile loopback listener (any bytes, then
  silence or a close) is refused with ``ExecutorError`` within the connect
  timeout (plus a margin), never a hang or another exception; any executor
  text parses or raises ``ValueError``/``TypeError``;
- a glove recording file loads (and then maps and segments into a gist in
  bounded time) or raises ``GloveFormatError``/``ValueError``/``TypeError``;
- a depth frame (sidecar fields and an image of any dtype, shape and format)
  loads as a valid ``DepthFrame`` or raises ``ValueError``/``TypeError``/
  ``FileNotFoundError``;
- accelerometer estimator settings in a scenario, and event recordings of any
  bytes, load or raise ``ValueError``;
- an OBJ mesh of any vertices and face indices loads or raises ``ValueError``;
- a MIDI mapping of any controls loads in a scenario or raises ``ValueError``.

Example counts follow the ``ci``/``long`` profiles of ``test_fuzz.py``, capped
lower here where one example costs up to a connect timeout.
"""

import json
import os
import socket
import tempfile
import threading
import time
from pathlib import Path

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

settings.register_profile("ci", max_examples=40, deadline=None, derandomize=True,
                          suppress_health_check=[HealthCheck.too_slow,
                                                 HealthCheck.function_scoped_fixture])
settings.register_profile("long",
                          max_examples=int(os.environ.get("HYPOTHESIS_MAX_EXAMPLES", 2000)),
                          deadline=None,
                          suppress_health_check=[HealthCheck.too_slow,
                                                 HealthCheck.function_scoped_fixture])
settings.load_profile(os.environ.get("HYPOTHESIS_PROFILE", "ci"))
REDUCED = os.environ.get("HYPOTHESIS_PROFILE", "ci") == "ci"


def _examples(ci: int):
    """``ci`` examples in the ci profile, the profile's count otherwise."""
    return settings(max_examples=ci if REDUCED else settings.default.max_examples)


numbers = st.one_of(
    st.floats(allow_nan=True, allow_infinity=True),
    st.sampled_from([0, -1, 1e-300, 1e300, 1e-12, 1e-9, 1e-4, 0.001, 0.01, 1.0, 640, 480]),
    st.integers(min_value=-(2**64), max_value=2**64),
)
scalars = st.one_of(numbers, st.text(max_size=8), st.booleans(), st.none())
values = st.recursive(scalars, lambda inner: st.one_of(
    st.lists(inner, max_size=4), st.dictionaries(st.text(max_size=6), inner, max_size=3)),
    max_leaves=10)


# -- dask:// addresses against hostile loopback listeners -------------------------------
@_examples(8)
@given(greeting=st.one_of(st.binary(max_size=40), st.sampled_from([
    b"HTTP/1.1 200 OK\r\n\r\n", b"\x01", b"\x10" + b"\x00" * 7, b"\x18" + b"\x00" * 15,
    (24).to_bytes(8, "little") + (1).to_bytes(8, "little") + (8).to_bytes(8, "little")
    + b"\x81\xa1a\x01" + b"\x00" * 4])),
    then=st.sampled_from(["close", "silence"]))
def test_a_hostile_listener_is_refused_within_the_timeout(greeting, then):
    from handle_drake.learning.cluster import ExecutorError
    from handle_drake.learning.dask_probe import probe_scheduler

    server = socket.socket()
    server.bind(("127.0.0.1", 0))
    server.listen(4)
    held = []

    def serve():
        try:
            conn, _ = server.accept()
        except OSError:
            return
        held.append(conn)
        try:
            conn.sendall(greeting)
            if then == "close":
                conn.close()
        except OSError:
            pass

    thread = threading.Thread(target=serve, daemon=True)
    thread.start()
    start = time.monotonic()
    try:
        with pytest.raises(ExecutorError):
            probe_scheduler(f"tcp://127.0.0.1:{server.getsockname()[1]}", 0.3)
        assert time.monotonic() - start < 0.3 + 2.0
    finally:
        server.close()
        for conn in held:
            conn.close()


@given(text=st.one_of(st.text(max_size=40), st.builds(
    lambda host, port: f"dask://{host}:{port}", st.text(max_size=12),
    st.one_of(st.integers(-5, 70000).map(str), st.text(max_size=6))), values))
def test_executor_text_parses_or_is_refused(text):
    from handle_drake.learning.cluster import ExecutorSpec

    try:
        spec = ExecutorSpec.parse(text)
    except (ValueError, TypeError):
        return
    assert spec.kind in ("local", "dask")


# -- glove recordings ---------------------------------------------------------------------
@st.composite
def glove_documents(draw):
    from handle_drake.inhand.glove import GLOVE_SENSORS

    n = draw(st.integers(0, 12))
    step = draw(st.sampled_from([1e-12, 1e-9, 1e-6, 1e-5, 1e-4, 0.01, 1.0, 1e300, -0.01]))
    time_stamps = [i * step for i in range(n)]
    if draw(st.booleans()):
        time_stamps = draw(st.lists(scalars, max_size=n + 1)) or time_stamps
    raw = [[0.1 * ((i + j) % 5) for j in range(22)] for i in range(n)]
    if draw(st.booleans()) and raw:
        raw[draw(st.integers(0, n - 1))][draw(st.integers(0, 21))] = draw(scalars)
    document = {"format": "handle_drake.glove", "version": 1, "sensors": list(GLOVE_SENSORS),
                "time": time_stamps, "raw": raw, "calibration": None, "meta": {}}
    for key in draw(st.lists(st.sampled_from(sorted(document)), max_size=2)):
        document[key] = draw(values)
    return document


@given(document=glove_documents())
def test_glove_files_load_or_are_refused(document):
    from handle_drake.inhand.gist import extract_gist
    from handle_drake.inhand.glove import load_glove
    from handle_drake.inhand.mapping import glove_to_shadow

    with tempfile.TemporaryDirectory() as folder:
        path = Path(folder) / "glove.json"
        path.write_text(json.dumps(document))
        try:
            recording = load_glove(path)
        except (ValueError, TypeError):
            return
    start = time.monotonic()
    try:
        extract_gist(recording.time, glove_to_shadow(recording))
    except ValueError:
        pass
    assert time.monotonic() - start < 5  # bounded: the sample-rate cap holds the window


# -- depth frames and sidecars ------------------------------------------------------------
FRAME_FIELDS = ["format", "version", "depth_png", "depth_scale", "width", "height", "K", "X_WC"]


@st.composite
def frames(draw):
    dtype = draw(st.sampled_from(["uint16", "uint8", "int32", "float32", "rgb", "bool"]))
    height, width = draw(st.integers(1, 6)), draw(st.integers(1, 6))
    fmt = draw(st.sampled_from(["PNG", "PNG", "TIFF", "BMP"]))
    sidecar = {"format": "handle_drake-depth-frame", "version": 1, "depth_png": "d.png",
               "depth_scale": 0.001, "width": width, "height": height,
               "K": [[5.0, 0, width / 2], [0, 5.0, height / 2], [0, 0, 1]],
               "X_WC": np.eye(4).tolist()}
    hostile = st.sampled_from([True, False, None, "64", "0.001", 99, 0, -1, 1e-300, 1e300,
                               12000, 48.0, 1.5])
    for key in draw(st.lists(st.sampled_from(FRAME_FIELDS), max_size=3)):
        sidecar[key] = draw(st.one_of(hostile, values, st.lists(st.lists(
            numbers, min_size=3, max_size=4), min_size=3, max_size=4)))
    if draw(st.booleans()):  # one entry of K or X_WC out of range, the rest a camera's
        key = draw(st.sampled_from(["K", "X_WC"]))
        matrix = [list(row) for row in sidecar[key]] if isinstance(sidecar[key], list) and \
            all(isinstance(r, list) for r in sidecar[key]) else None
        if matrix and matrix[0]:
            i = draw(st.integers(0, len(matrix) - 1))
            if matrix[i]:
                matrix[i][draw(st.integers(0, len(matrix[i]) - 1))] = draw(hostile)
            sidecar[key] = matrix
    return dtype, (height, width), fmt, sidecar, draw(st.integers(0, 2**16))


@given(frame=frames())
def test_depth_frames_load_or_are_refused(frame):
    from PIL import Image

    from handle_drake.perception.frames import DepthFrame, load_frame

    dtype, shape, fmt, sidecar, value = frame
    if dtype == "rgb":
        pixels = np.full((*shape, 3), value % 256, np.uint8)
    elif dtype == "bool":
        pixels = np.full(shape, value % 2, bool)
    else:
        pixels = np.full(shape, value, np.int64).astype(dtype)  # wraps around, as a file may
    with tempfile.TemporaryDirectory() as folder:
        try:
            Image.fromarray(pixels).save(Path(folder) / "d.png", format=fmt)
        except (OSError, KeyError, TypeError):  # a format that cannot hold this dtype
            return
        path = Path(folder) / "frame.json"
        path.write_text(json.dumps(sidecar))
        try:
            loaded = load_frame(path)
        except (ValueError, TypeError, FileNotFoundError):
            return
    # what loads is a camera: a 16-bit PNG, numbers of the right kind, intrinsics and a
    # pose a camera can have
    assert isinstance(loaded, DepthFrame) and loaded.depth.dtype == np.float32
    assert fmt == "PNG" and dtype in ("uint16", "int32")
    assert sidecar["version"] == 1 and not isinstance(sidecar["depth_scale"], bool)
    assert 1e-6 <= sidecar["depth_scale"] <= 0.01
    assert all(type(sidecar[k]) is int for k in ("width", "height"))
    K, X = loaded.K, loaded.X_WC
    assert 1 <= K[0, 0] <= 1e5 and 1 <= K[1, 1] <= 1e5
    assert 0 <= K[0, 2] <= shape[1] and 0 <= K[1, 2] <= shape[0]
    assert np.all(X[3] == (0, 0, 0, 1)) and np.linalg.norm(X[:3, 3]) <= 100
    points = loaded.points()
    assert np.all(np.isfinite(points)) and np.all(np.abs(points) < 1e4)


# -- accelerometer configs and recordings -------------------------------------------------
ESTIMATOR_KEYS = ["window", "rest_window", "free_fall_threshold", "free_fall_duration",
                  "slip_angle_tol", "still_tol", "settle_time", "bogus"]


@given(settings_=st.dictionaries(st.sampled_from(ESTIMATOR_KEYS), st.one_of(
    st.sampled_from([0.5, 1.5, 7.0, 100.0, 1e9, 1e300]), scalars), max_size=3),
       device=st.sampled_from(["", "", "", "joywarrior24f14", "nope"]))
def test_accelerometer_settings_load_or_are_refused(settings_, device):
    import yaml

    from handle_drake.scenario import LoadScenario

    text = yaml.safe_dump({"object": {"accelerometer": {"estimators": settings_,
                                                        "device": device}}})
    try:
        scenario = LoadScenario(data=text)
    except (ValueError, TypeError):
        return
    params = scenario.object.accelerometer.estimator_params()
    assert 0 < params.free_fall_threshold <= 1.0 and params.window <= 60


@given(data=st.one_of(st.binary(max_size=200), st.lists(st.tuples(
    numbers, st.integers(-5, 70000), st.integers(-5, 70000), numbers), max_size=6).map(
    lambda rows: "\n".join(" ".join(str(v) for v in row) for row in rows).encode())))
def test_event_recordings_load_or_are_refused(data):
    from handle_drake.instruments.evdev_driver import load_events

    with tempfile.TemporaryDirectory() as folder:
        path = Path(folder) / "events.txt"
        path.write_bytes(data)
        try:
            events = load_events(path)
        except UnicodeError as error:  # a ValueError, but not naming the recording
            raise AssertionError(f"undecoded: {error}") from None
        except ValueError as error:
            assert "\n" not in str(error).strip()
            return
    events.read_events(1e9)


# -- meshes ----------------------------------------------------------------------------------
@_examples(25)
@given(vertices=st.one_of(
    st.just([(0, 0, 0), (0.05, 0, 0), (0, 0.05, 0), (0, 0, 0.05)]),  # a tetrahedron
    st.lists(st.tuples(*[st.one_of(st.floats(-0.05, 0.05), numbers)] * 3), max_size=8)),
       faces=st.one_of(
           st.just([(1, 3, 2), (1, 2, 4), (1, 4, 3), (2, 3, 4)]).flatmap(  # closed, then spoilt
               lambda closed: st.lists(st.tuples(*[st.one_of(st.just(0), st.integers(-4, 4))]
                                                 * 3), min_size=1, max_size=2).map(
                   lambda extra: closed + extra)),
           st.lists(st.tuples(*[st.integers(-10, 10)] * 3), max_size=12)),
       slashes=st.booleans())
def test_obj_meshes_load_or_are_refused(vertices, faces, slashes):
    from handle_drake.objects.mesh import MeshObjectSpec

    lines = [f"v {x} {y} {z}" for x, y, z in vertices]
    lines += [("f " + " ".join(f"{i}/{i}/{i}" if slashes else str(i) for i in face))
              for face in faces]
    with tempfile.TemporaryDirectory() as folder:
        path = Path(folder) / "m.obj"
        path.write_text("\n".join(lines) + "\n")
        try:
            MeshObjectSpec(file=str(path))
        except (ValueError, TypeError):
            return
    assert all(0 not in face for face in faces)  # OBJ counts from 1: index 0 is no vertex


# -- MIDI mappings ------------------------------------------------------------------------
@_examples(25)
@given(controls=st.lists(st.one_of(
    st.fixed_dictionaries({  # well-typed: the name and kind decide
        "name": st.sampled_from(["fader1", "knob3", "jog", "mode", "slider1", "button2"]),
        "kind": st.sampled_from(["fader", "knob", "jog", "button"]),
        "channel": st.just(0), "number": st.integers(0, 127)}),
    st.fixed_dictionaries({}, optional={
        "name": st.one_of(st.sampled_from(["fader1", "slider1", ""]), scalars),
        "kind": st.one_of(st.sampled_from(["fader", "pad"]), scalars),
        "channel": st.one_of(st.integers(-2, 17), scalars),
        "number": st.one_of(st.integers(-2, 130), scalars)})), max_size=3))
def test_midi_mappings_load_or_are_refused(controls):
    import yaml

    from handle_drake.scenario import LoadScenario

    with tempfile.TemporaryDirectory() as folder:
        path = Path(folder) / "mapping.yaml"
        path.write_text(yaml.safe_dump({"controls": controls}))
        try:
            LoadScenario(data=f"midi_controller: {{mapping: '{path}'}}")
        except (ValueError, TypeError, FileNotFoundError):
            return
    from handle_drake.midi.device import control_layout

    layout = {c.name: c.kind for c in control_layout()}
    for control in controls:  # what loads is on the device, with its kind
        assert layout[control["name"]] == control.get("kind", "fader")
