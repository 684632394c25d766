"""Hostile input, third wave (issue 31): Dask addresses against hostile listeners,
glove recordings, depth frames, accelerometer configs and recordings, meshes,
MIDI mappings, output paths checked first, pool workers that die with their
parent, and the messages of a few refusals.

Every case was found by ``tools/hostile_probe.py third`` on the code before
these checks: a hang, a traceback, or a silent accept. Each test here fails on
that code (hangs are bounded by the test itself: a thread joined with a guard).
"""

import json
import os
import signal
import socket
import subprocess
import sys
import textwrap
import threading
import time
import zlib

import numpy as np
import pytest
import trimesh
from cli_runner import cli_exit
from PIL import Image

from handle_drake.scenario import LoadScenario, ScenarioError


# --------------------------------------------------------------- dask:// addresses
def _listener(kind):
    """A loopback listener that accepts and then: 'silent' says nothing, 'one' sends
    one byte, 'garbage' random bytes, 'http' an HTTP answer; each holds the socket."""
    server = socket.socket()
    server.bind(("127.0.0.1", 0))
    server.listen(16)
    held = []
    payload = {"silent": b"", "one": b"\x01", "http": b"HTTP/1.1 200 OK\r\nContent-Length: 0"
               b"\r\n\r\n", "garbage": np.random.default_rng(3).bytes(64)}[kind]

    def serve():
        while True:
            try:
                conn, _ = server.accept()
            except OSError:
                return
            held.append(conn)
            if payload:
                conn.sendall(payload)

    threading.Thread(target=serve, daemon=True).start()
    return server, held


@pytest.mark.parametrize("kind", ["silent", "one", "garbage", "http"])
def test_a_hostile_listener_as_dask_address_fails_within_the_connect_timeout(kind, tmp_path):
    import distributed  # noqa: F401 - loaded before the clock starts (seconds on a busy host)

    from handle_drake.learning.cluster import ExecutorError, trial_executor

    server, held = _listener(kind)
    address = f"dask://127.0.0.1:{server.getsockname()[1]}"
    outcome = {}

    def connect():
        start = time.monotonic()
        try:
            with trial_executor(address, connect_timeout=1.0):
                outcome["error"] = None
        except Exception as error:  # noqa: BLE001 - the test looks at its type
            outcome["error"] = error
        outcome["seconds"] = time.monotonic() - start

    thread = threading.Thread(target=connect, daemon=True)
    thread.start()
    thread.join(20)  # a guard: before the fix, 'silent' held past 100 s
    try:
        assert not thread.is_alive(), f"{kind} listener: still connecting after 20 s"
        assert isinstance(outcome["error"], ExecutorError), repr(outcome["error"])
        assert "dask://127.0.0.1" in str(outcome["error"])
        assert outcome["seconds"] < 1.0 + 2.0  # the timeout, plus a margin for a loaded host
    finally:
        server.close()
        for conn in held:
            conn.close()


def test_the_command_refuses_a_hostile_dask_address_before_writing_anything(tmp_path, capsys):
    server, held = _listener("http")
    db = tmp_path / "never.sqlite"
    try:
        code, err = cli_exit(["babble", "--executor", f"dask://127.0.0.1:{server.getsockname()[1]}",
                              "--connect-timeout", "1", "--db", str(db), "--no-plot"], capsys)
    finally:
        server.close()
        for conn in held:
            conn.close()
    assert code == 2 and "not a Dask scheduler" in err
    assert not db.exists()


@pytest.mark.parametrize("command", [["babble"], ["inhand"], ["report", "--reduced"]])
def test_connect_timeout_without_a_dask_address_is_refused(command, tmp_path, capsys):
    code, err = cli_exit([*command, "--connect-timeout", "3", "--executor", "local"], capsys)
    assert code == 2 and "--connect-timeout" in err and "dask://" in err


# ---------------------------------------------------------------------- glove files
def _glove(time_stamps, raw=None):
    from handle_drake.apps.inhand.glove import GLOVE_SENSORS

    n = len(time_stamps)
    return {"format": "handle_drake.glove", "version": 1, "sensors": list(GLOVE_SENSORS),
            "time": time_stamps, "raw": raw if raw is not None else [[0.0] * 22] * n,
            "calibration": None, "meta": {}}


@pytest.mark.parametrize("step", [1e-9, 1e-12])
def test_glove_time_stamps_closer_than_the_sample_rate_cap_are_refused(step, tmp_path):
    from handle_drake.apps.inhand.glove import MAX_SAMPLE_RATE, GloveFormatError, load_glove
    path = tmp_path / "fast.json"
    path.write_text(json.dumps(_glove([i * step for i in range(200)])))
    start = time.monotonic()
    with pytest.raises(GloveFormatError, match=r"time: .*samples per second"):
        load_glove(path)
    assert time.monotonic() - start < 5
    # at the cap itself (k / rate, rounded as floats are): accepted
    path.write_text(json.dumps(_glove([i / MAX_SAMPLE_RATE for i in range(200)])))
    assert load_glove(path).time.size == 200


@pytest.mark.parametrize("field,value", [("time", ["0", "1", "2"]), ("time", [0, True, 2]),
                                         ("raw", [["1"] * 22] * 3)])
def test_glove_strings_or_booleans_as_numbers_are_refused(field, value, tmp_path):
    from handle_drake.apps.inhand.glove import GloveFormatError, load_glove

    document = _glove([0.0, 0.01, 0.02])
    document[field] = value
    path = tmp_path / "strings.json"
    path.write_text(json.dumps(document))
    with pytest.raises(GloveFormatError, match=rf"{field}.*expected numbers"):
        load_glove(path)


# --------------------------------------------------------------------- depth frames
def _frame(tmp_path, **changes):
    from handle_drake.devices.camera.frames import DepthFrame, save_frame

    depth = np.full((48, 64), 0.8)
    K = [[60.0, 0, 32.0], [0, 60.0, 24.0], [0, 0, 1]]
    path = save_frame(tmp_path / "cam", DepthFrame(depth, K, np.eye(4)))
    meta = json.loads(path.read_text())
    meta.update(changes)
    path.write_text(json.dumps(meta))
    return path


def _png_header_only(path, width, height):
    """A 16-bit grey PNG whose header claims width x height (no pixel data needed:
    the size is refused before decoding)."""
    def chunk(kind, data):
        return (len(data).to_bytes(4, "big") + kind + data
                + zlib.crc32(kind + data).to_bytes(4, "big"))

    ihdr = width.to_bytes(4, "big") + height.to_bytes(4, "big") + bytes([16, 0, 0, 0, 0])
    path.write_bytes(b"\x89PNG\r\n\x1a\n" + chunk(b"IHDR", ihdr)
                     + chunk(b"IDAT", zlib.compress(b"")) + chunk(b"IEND", b""))


FRAME_CASES = {
    "focal length 1e-300": ({"K": [[1e-300, 0, 32], [0, 60, 24], [0, 0, 1]]}, "fx"),
    "focal length 1e300": ({"K": [[60, 0, 32], [0, 1e300, 24], [0, 0, 1]]}, "fy"),
    "principal point 1e12": ({"K": [[60, 0, 1e12], [0, 60, 24], [0, 0, 1]]}, "cx"),
    "junk last row": ({"X_WC": [[1, 0, 0, 0], [0, 1, 0, 0], [0, 0, 1, 0], [5, 5, 5, 5]]},
                      "X_WC"),
    "camera 1e12 m away": ({"X_WC": [[1, 0, 0, 1e12], [0, 1, 0, 0], [0, 0, 1, 0],
                                     [0, 0, 0, 1]]}, "X_WC"),
    "depth_scale true": ({"depth_scale": True}, "depth_scale"),
    "depth_scale 1e300": ({"depth_scale": 1e300}, "depth_scale"),
    "version 99": ({"version": 99}, "version"),
    "width as a string": ({"width": "64"}, "width"),
    "height 1e9": ({"height": 10**9}, "height"),
}


@pytest.mark.parametrize("case", FRAME_CASES, ids=list(FRAME_CASES))
def test_a_depth_frame_sidecar_out_of_range_is_refused_naming_the_field(case, tmp_path):
    from handle_drake.devices.camera.frames import load_frame

    changes, word = FRAME_CASES[case]
    with pytest.raises(ValueError, match=word):
        load_frame(_frame(tmp_path, **changes))


def test_an_8_bit_png_or_a_32_bit_tiff_is_refused_as_depth(tmp_path):
    from handle_drake.devices.camera.frames import load_frame

    path = _frame(tmp_path)
    png = path.with_suffix(".png")
    Image.fromarray(np.full((48, 64), 200, np.uint8)).save(png)  # 8-bit: the object vanished
    with pytest.raises(ValueError, match="16-bit"):
        load_frame(path)
    Image.fromarray(np.full((48, 64), -99_999_999, np.int32)).save(png, format="TIFF")
    with pytest.raises(ValueError, match="expected a PNG image, got TIFF"):
        load_frame(path)


def test_a_depth_image_above_the_pixel_cap_is_refused_before_decoding(tmp_path):
    from handle_drake.devices.camera.frames import MAX_PIXELS, load_frame

    path = _frame(tmp_path, width=12000, height=9000)  # 108 Mpx, as the sidecar says
    with pytest.raises(ValueError, match="width, height"):
        load_frame(path)
    path = _frame(tmp_path)
    _png_header_only(path.with_suffix(".png"), 12000, 9000)
    start = time.monotonic()
    with pytest.raises(ValueError, match=f"at most {MAX_PIXELS} pixels"):
        load_frame(path)
    assert time.monotonic() - start < 2


def test_the_perceive_command_refuses_a_bad_frame_with_exit_2(tmp_path, capsys):
    path = _frame(tmp_path, depth_scale=True)
    code, err = cli_exit(["perceive", "--frame", str(path)], capsys)
    assert code == 2 and "depth_scale" in err


# -------------------------------------------------------------------- accelerometer
def test_evdev_device_dev_zero_is_a_value_error_naming_the_field():
    pytest.importorskip("evdev")
    from handle_drake.devices.accelerometer.evdev_driver import open_device

    with pytest.raises(ValueError, match="evdev_device: /dev/zero is not an input event device"):
        open_device("/dev/zero")
    with pytest.raises(ValueError, match="evdev_device: /tmp is not an input event device"):
        open_device("/tmp")


def test_a_recording_that_is_binary_a_directory_a_fifo_or_a_device_is_refused(tmp_path):
    from handle_drake.devices.accelerometer.evdev_driver import load_events

    binary = tmp_path / "binary.txt"
    binary.write_bytes(np.random.default_rng(0).bytes(200) + b"\xff")
    with pytest.raises(ValueError, match="event recording file .*UTF-8"):
        load_events(binary)
    fifo = tmp_path / "fifo"
    os.mkfifo(fifo)
    for path, word in ((tmp_path, "directory"), (fifo, "FIFO"), ("/dev/zero", "device")):
        with pytest.raises(ValueError, match=word):
            load_events(path)
    with pytest.raises(FileNotFoundError, match="not found"):
        load_events(tmp_path / "missing.txt")


@pytest.mark.parametrize("name,value", [("free_fall_threshold", 1e300),
                                        ("free_fall_threshold", 1.5), ("window", 1e9),
                                        ("slip_angle_tol", 7.0)])
def test_estimator_thresholds_beyond_their_meaning_are_refused(name, value):
    with pytest.raises(ScenarioError, match=rf"estimators\.{name}: expected a value in"):
        LoadScenario(data=f"object: {{accelerometer: {{estimators: {{{name}: {value}}}}}}}")
    LoadScenario(data="object: {accelerometer: {estimators: {free_fall_threshold: 0.5}}}")


# ------------------------------------------------------------------------------ meshes
def test_an_obj_face_index_0_is_refused(tmp_path):
    from handle_drake.geometry.objects.mesh import MeshObjectSpec

    path = tmp_path / "zero.obj"
    box = trimesh.creation.box((0.05, 0.05, 0.05))
    lines = [f"v {x} {y} {z}" for x, y, z in box.vertices]
    faces = box.faces + 1
    faces[3, 1] = 0  # OBJ counts from 1: trimesh read 0 as the last vertex
    lines += [f"f {a} {b} {c}" for a, b, c in faces]
    path.write_text("\n".join(lines) + "\n")
    with pytest.raises(ValueError, match=r"zero\.obj:\d+: face index 0"):
        MeshObjectSpec(file=str(path))
    path.write_text("\n".join(lines).replace(" 0", " 0/0/0", 1) + "\n")  # with texture slots
    with pytest.raises(ValueError, match="face index 0"):
        MeshObjectSpec(file=str(path))


def test_a_mesh_above_the_triangle_cap_is_refused(tmp_path, monkeypatch):
    from handle_drake.geometry.objects import mesh

    path = tmp_path / "ball.stl"
    trimesh.creation.icosphere(subdivisions=2, radius=0.03).export(path)  # 320 triangles
    monkeypatch.setattr(mesh, "MAX_TRIANGLES", 319)
    with pytest.raises(ValueError, match="320 triangles, expected at most 319"):
        mesh.MeshObjectSpec(file=str(path))
    monkeypatch.setattr(mesh, "MAX_TRIANGLES", 320)
    mesh.MeshObjectSpec(file=str(path))


def test_ctrl_c_stops_an_isolated_decomposition_promptly():
    """The decomposition runs in a child process that ignores SIGINT; the parent
    kills it on KeyboardInterrupt. Before: the parent waited for the child's end
    (a 200k-triangle torus: still decomposing 10 s after SIGINT)."""
    from handle_drake.geometry.objects.mesh import _isolated

    # Ctrl-C as a terminal delivers it: Python's own handler, whatever an earlier test in
    # this worker process (a Dask cluster, a CAN command's stop logic) left installed.
    previous = signal.signal(signal.SIGINT, signal.default_int_handler)
    timer = threading.Timer(1.0, os.kill, (os.getpid(), signal.SIGINT))
    start = time.monotonic()
    timer.start()
    try:
        with pytest.raises(KeyboardInterrupt):
            _isolated(time.sleep, 30.0)  # stands in for CoACD: C++ that never looks at signals
    finally:
        timer.cancel()
        signal.signal(signal.SIGINT, previous)
    assert time.monotonic() - start < 10
    assert _isolated(divmod, 7, 2) == (3, 1)  # and it still runs


# ------------------------------------------------------------------------ MIDI mapping
def test_a_mapping_naming_controls_the_device_lacks_is_refused(tmp_path):
    path = tmp_path / "mapping.yaml"
    path.write_text("controls:\n  - {name: fader1, kind: fader, channel: 0, number: 20}\n"
                    "  - {name: slider9, kind: fader, channel: 0, number: 21}\n")
    with pytest.raises(ScenarioError, match=r"controls\[1\]\.name: .*no control 'slider9'"):
        LoadScenario(data=f"midi_controller: {{mapping: {path}}}")
    path.write_text("controls:\n  - {name: jog, kind: fader, channel: 0, number: 21}\n")
    with pytest.raises(ScenarioError, match=r"controls\[0\] \('jog'\)\.kind: .* is a jog"):
        LoadScenario(data=f"midi_controller: {{mapping: {path}}}")


# ------------------------------------------------------------------------ output paths
@pytest.mark.parametrize("argv", [
    "babble --trials 2 --plot /proc/x.png --db {tmp}/b.sqlite",
    "instruments --quick --plot /proc/x.png",
    "instruments --quick --json /proc/x.json",
    "inhand --trials 1 --html /proc/x.html --db {tmp}/i.sqlite",
    "report --reduced --out /proc/report",
    "perceive --frame {tmp}/cam.json --save-frames /proc/frames",
    "grasp --class tripod --size 0.05 --save-scenario /proc/s.yaml",
    "demo --html /proc/demo.html",
])
def test_an_output_the_system_refuses_is_named_before_any_work(argv, tmp_path, capsys):
    _frame(tmp_path)
    start = time.monotonic()
    code, err = cli_exit(argv.format(tmp=tmp_path).split(), capsys)
    option = next(a for a in argv.split() if a.startswith("--") and "/proc" in
                  argv.split()[argv.split().index(a) + 1])
    assert code == 2 and f"{option}: cannot create" in err, err
    assert time.monotonic() - start < 5  # refused before the trials / simulation
    assert not list(tmp_path.glob("*.sqlite"))


# --------------------------------------------------------------------- orphan workers
def _children(pid):
    out = []
    for entry in os.listdir("/proc"):
        if entry.isdigit():
            try:
                with open(f"/proc/{entry}/stat") as file:
                    fields = file.read().rsplit(")", 1)[1].split()
            except OSError:
                continue
            if int(fields[1]) == pid:
                out.append(int(entry))
    return out


def _alive(pid):
    try:
        with open(f"/proc/{pid}/stat") as file:
            return file.read().rsplit(")", 1)[1].split()[0] != "Z"
    except OSError:
        return False


def test_pool_workers_die_with_a_parent_killed_with_sigkill():
    script = textwrap.dedent("""
        import sys, time
        from handle_drake.learning.cluster import LocalPool
        pool = LocalPool(2)
        futures = [pool.submit(time.sleep, 60) for _ in range(2)]
        time.sleep(0.5)
        print("ready", flush=True)
        time.sleep(60)
    """)
    parent = subprocess.Popen([sys.executable, "-c", script], stdout=subprocess.PIPE, text=True)
    try:
        assert parent.stdout.readline().strip() == "ready"
        deadline = time.monotonic() + 30
        while len(workers := _children(parent.pid)) < 2 and time.monotonic() < deadline:
            time.sleep(0.2)
        workers = [w for w in workers if _alive(w)]
        assert len(workers) >= 2, workers
        parent.kill()
        parent.wait()
        deadline = time.monotonic() + 5
        while any(_alive(w) for w in workers) and time.monotonic() < deadline:
            time.sleep(0.1)
        left = [w for w in workers if _alive(w)]
        for w in left:  # before the fix: alive; do not leave them behind
            os.kill(w, signal.SIGKILL)
        assert not left, f"workers {left} outlived their parent by 5 s"
    finally:
        if parent.poll() is None:
            parent.kill()


# ---------------------------------------------------------------------------- messages
@pytest.mark.parametrize("argv,words", [
    ("babble --size 1e300", ["size", "[0.01, 0.5] m"]),
    ("babble --run-id ", ["--run-id", "non-empty"]),
    ("can-server --channel ", ["--channel", "non-empty"]),
])
def test_refusals_say_why(argv, words, tmp_path, capsys):
    args = argv.split(" ")
    if args[0] == "babble":  # bounded on code that would run it
        args += ["--trials", "1", "--no-plot", "--no-progress", "--db", str(tmp_path / "x.sqlite")]
    code, err = cli_exit(args, capsys)
    assert code == 2, err
    for word in words:
        assert word in err, (word, err)
    assert not (tmp_path / "x.sqlite").exists()


def test_a_nan_rotation_names_the_field():
    with pytest.raises(ScenarioError, match=r"object\.X_WO\.rotation\.deg: expected a finite"):
        LoadScenario(data="object: {X_WO: {rotation: !Rpy {deg: [.nan, 0, 0]}}}")
    with pytest.raises(ScenarioError, match=r"midi_controller\.X_WC\.rotation\.axis"):
        LoadScenario(data="midi_controller: {X_WC: {rotation: !AngleAxis {angle_deg: 3, "
                          "axis: [.nan, 0, 1]}}}")


def test_a_comment_only_scenario_is_an_empty_one():
    from handle_drake.scenario import DumpScenario

    assert DumpScenario(LoadScenario(data="# nothing yet\n\n  # really\n")) == \
        DumpScenario(LoadScenario(data=""))


def test_port_0_is_refused_with_the_range_that_applies():
    from handle_drake.devices.can_hand.config import CanHandDriverConfig

    with pytest.raises(ValueError, match=r"port: expected an integer port in 1\.\.65535, got 0"):
        CanHandDriverConfig(port=0).validate()
    with pytest.raises(ScenarioError, match=r"port: expected an integer port in 1\.\.65535"):
        LoadScenario(data="driver: !CanHandDriver {port: 0}")
