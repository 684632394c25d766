"""Hostile-input probe set (issues 15, 31, 46): tries bad inputs on each part and tabulates
outcomes. A test tool, not a benchmark (it measures no speed): ``tests/test_hostile_probe.py``
runs its fourth wave's quick surfaces.

Run: ``PYTHONPATH=. python tools/hostile_probe.py`` (about 2 minutes; it starts
a CAN server and simulated hand as subprocesses on a random loopback multicast
group). Outcomes per probe:

- clean: refused with a ValueError/TypeError/FileNotFoundError (or the part's
  documented subclass) naming the field, or CLI exit 2 with a one-line message;
  for the CAN server: both processes alive and STATE still streaming;
- traceback: any other exception / a traceback on stderr / a dead process;
- hang: no answer within the probe's time limit;
- wrong: accepted although it is nonsense, or a message without the field.

Writes ``out/hostile_probe/hostile_probe.json``. ``hostile_probe.py third before``
(or ``after``) runs issue 31's surfaces only (each case in a forked child, killed
at its time limit) and writes ``hostile_probe_third_<label>.json``; ``fourth``
likewise issue 46's (pick and its grasp database and scenes, in-hand options, seeds,
numba's cache, trial logs, messages) into ``hostile_probe_fourth_<label>.json``.
``PROBE_ONLY=<part>`` limits it to one surface, ``PROBE_VERBOSE=1`` prints each case.
"""

import argparse
import contextlib
import io
import json
import os
import random
import signal
import socket
import sqlite3
import subprocess
import sys
import tempfile
import time
import zlib
from pathlib import Path

import numpy as np

from handle_drake.base.results import ResultsRun, add_page_arguments

ROOT = Path(__file__).resolve().parents[1]
OUT = ROOT / "out" / "hostile_probe"
RESULTS = {}


class Hang(Exception):
    pass


def _alarm(signum, frame):
    raise Hang


@contextlib.contextmanager
def time_limit(seconds):
    signal.signal(signal.SIGALRM, _alarm)
    signal.setitimer(signal.ITIMER_REAL, seconds)
    try:
        yield
    finally:
        signal.setitimer(signal.ITIMER_REAL, 0)


def record(part, outcome, probe):
    RESULTS.setdefault(part, {"tried": 0, "clean": 0, "traceback": 0, "hang": 0, "wrong": 0,
                              "failures": []})
    if part in ("kill -9", "process checks") or probe.startswith("Ctrl-C"):  # keep the figures
        RESULTS[part].setdefault("measured", []).append(f"{outcome}: {probe}")
    RESULTS[part]["tried"] += 1
    RESULTS[part][outcome] += 1
    if outcome != "clean":
        RESULTS[part]["failures"].append(f"{outcome}: {probe[:120]}")


def probe_scenarios():
    from handle_drake.scenario import LoadScenario

    wrist = "hand: {mount: !FloatingWrist {}}\n"
    cases = {  # text -> a word the refusal must name
        "object: {size: 1e300}": "object.size", "object: {size: 1e-300}": "object.size",
        "object: {size: -1}": "object.size", "object: {size: .nan}": "object.size",
        "object: {size: big}": "object.size", "object: {mass: 1e-30}": "object.mass",
        "object: {mass: 1e30}": "object.mass", "object: {mu: -1}": "object.mu",
        "object: {mu: 1e9}": "object.mu", "object: {kind: blob}": "object.kind",
        "object: {kind: cuboid, dimensions: {depth: 1e300}}": "depth",
        "object: {kind: cuboid, dimensions: {depth: 0}}": "depth",
        "object: {X_WO: {translation: [1e300, 0, 0]}}": "object.X_WO",
        "object: {X_WO: {translation: [0, 0]}}": "translation",
        **{f"plant_config: {{time_step: {v}}}": "plant_config.time_step"
           for v in ("1e300", "10", "1e-9", "0", "-1", ".nan", "fast")},
        "plant_config: {penetration_allowance: 0}": "penetration_allowance",
        "plant_config: {stiction_tolerance: .inf}": "stiction_tolerance",
        "plant_config: {sap_near_rigid_threshold: -1}": "sap_near_rigid_threshold",
        "plant_config: {contact_surface_representation: quad}": "contact_surface_representation",
        "plant_config: {contact_model: hydroelastic}": "hydroelastic_with_fallback",
        "plant_config: [1, 2]": "plant_config",
        "time_step: 10": "plant_config.time_step",  # a deprecated key: translated, then checked
        "simulation_duration: 1e300": "simulation_duration",
        "simulation_duration: .inf": "simulation_duration",
        "plant_config: {time_step: 1e-5}\nsimulation_duration: 3000": "steps",
        "visualization: {publish_period: 1e-12}": "visualization.publish_period",
        "hand: {mount: !FloatingWrist {translation_kp: -5}}": "translation_kp",
        "hand: {mount: !FloatingWrist {translation_kd: .inf}}": "translation_kd",
        "hand: {mount: !FloatingWrist {rotation_kp: .nan}}": "rotation_kp",
        "hand: {mount: !FloatingWrist {rotation_kd: 1e300}}": "rotation_kd",
        "hand: {mount: !FixedMount {X_WB: {rotation: !Uniform {}}}}": "rotation",
        "hand: {mount: !FixedMount {X_WB: {rotation: !AngleAxis {angle_deg: 3, axis: [0, 0, 0]}}}}":
            "axis",
        "hand: {mount: !FixedMount {X_WB: {rotation: !AngleAxis {angle_deg: 3, "
        "axis: [1e-320, 0, 0]}}}}": "axis",
        "hand: {mount: !FixedMount {X_WB: {rotation: !Rpy {deg: [1e300, 0, 0]}}}}": "deg",
        "hand: {mount: !FixedMount {X_WB: {base_frame: palm}}}": "base_frame",
        "hand: {kind: octopus}": "hand.kind", "hand: {coupling_ratio: -1}": "coupling_ratio",
        "hand: {initial_position: {nojoint: 1}}": "initial_position",
        "hand: {initial_position: {FFJ3: 1e300}}": "FFJ3",
        "hand: [1, 2]": "hand", "hand: 5": "hand",
        wrist + "script: [{time: 0.5, wrist: [1e6, 0, 0, 0, 0, 0]}]": "wrist",
        wrist + "script: [{time: 0.5, wrist: [0, 0]}]": "wrist",
        "script: [{time: 0.5, wrist: [0, 0, 0, 0, 0, 0]}]": "wrist",
        "script: [{time: 1}, {time: 0.5}]": "time", "script: [{time: -1}]": "time",
        "script: [{time: 1e300}]": "time",
        "plant_config: {time_step: 0.001, time_step: 0.002}": "duplicate",
        "time_step: 0.001\nplant_config: {time_step: 0.002}": "plant_config.time_step",
        "object: {size: 1, size: 2}": "duplicate",
        "driver: 5": "driver", "driver: !Foo {}": "driver", "!Foo {}": "!Foo",
        "driver: !CanHandDriver {port: 0}": "port", "driver: !CanHandDriver {port: 1e9}": "port",
        "driver: !CanHandDriver {period: 0}": "period",
        "driver: !SimHandDriver {control_period: 1e300}": "control_period",
        "plant_config: {contact_model: magic}": "plant_config.contact_model",
        "plant_config: {discrete_contact_approximation: tamsi}": "tamsi",
        "random_seed: -1": "random_seed", "random_seed: 1e300": "random_seed",
        "colour: red": "colour", "object: {kind: " + "x" * 1_000_000 + "}": "object.kind",
        "- 1\n- 2": "mapping", "5": "mapping", "{a: [": "YAML", "a: &a [*a]": "",
        "table: {size_x: 0}": "size_x", "table: {top_height: .nan}": "top_height",
    }
    for text, word in cases.items():
        try:
            with time_limit(20):
                LoadScenario(data=text)
            record("scenario loader", "wrong", f"accepted {text!r}")
        except Hang:
            record("scenario loader", "hang", text)
        except (ValueError, TypeError, FileNotFoundError) as error:
            ok = word in str(error) and len(str(error)) < 1000
            record("scenario loader", "clean" if ok else "wrong",
                   f"{text[:60]!r} -> {str(error)[:80]}")
        except BaseException as error:  # noqa: BLE001
            record("scenario loader", "traceback", f"{text[:60]!r}: {type(error).__name__}")


def probe_cli(tmp):

    (tmp / "ok.yaml").write_text("simulation_duration: 0.01\n")
    (tmp / "bad.yaml").write_text("plant_config: {time_step: 10}\n")
    (tmp / "dir").mkdir()
    os.mkfifo(tmp / "fifo")
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        free = s.getsockname()[1]
    (tmp / "can.yaml").write_text(f"driver: !CanHandDriver {{port: {free}}}\n"
                                  "simulation_duration: 0.01\n")
    busy = socket.socket()
    busy.bind(("127.0.0.1", 0))
    busy.listen(1)
    long = "a" * 300
    ok = str(tmp / "ok.yaml")
    argvs = [
        ["simulate", str(tmp / "bad.yaml")], ["simulate", str(tmp / "dir")],
        ["simulate", str(tmp / "fifo")], ["simulate", str(tmp / "missing.yaml")],
        ["simulate", ok, "--html", str(tmp)], ["simulate", ok, "--html", f"{tmp}/{long}.html"],
        ["simulate", ok, "--html", f"{tmp}/ok.yaml/x.html"],
        ["simulate", ok, "--duration", "1e300"],
        ["simulate", ok, "--duration", "nan"], ["simulate", ok, "--duration", "-1"],
        ["simulate", ok, "--hardware"], ["simulate", str(tmp / "can.yaml"), "--hardware"],
        ["simulate", ok, "--override", "driver: 5"], ["simulate", ok, "--override", "!Foo {}"],
        ["simulate", ok, "--override", "plant_config: {time_step: 0.001, time_step: 0.002}"],
        ["babble", "--db", str(tmp)], ["babble", "--db", f"{tmp}/ok.yaml/x.sqlite"],
        ["babble", "--db", f"{tmp}/{long}.sqlite"], ["babble", "--trials", "-5"],
        ["babble", "--trials", "big"], ["babble", "--db", ok],
        ["report", "--out", ok], ["report", "--out", f"{tmp}/{long}"],
        ["grasp", "--save-scenario", str(tmp)], ["grasp", "--html", str(tmp)],
        ["grasp", "--size", "1e300"], ["grasp", "--size", "-1"], ["grasp", "--class", "nope"],
        ["synergies", str(tmp / "dir")], ["synergies", str(tmp / "fifo")],
        ["synergies", ok, "--plot", str(tmp)], ["synergies", ok, "--k-max", "-3"],
        ["can-server", "--listen", f"127.0.0.1:{busy.getsockname()[1]}", "--bus", "virtual"],
        ["can-server", "--listen", "192.0.2.1:0", "--bus", "virtual"],
        ["can-server", "--listen", "nope"], ["can-server", "--listen", "127.0.0.1:99999"],
        ["can-server", "--max-clients", "0", "--bus", "virtual"],
        ["can-server", "--multicast-interface", "eth0"],
        ["can-sim", "--bus", "socketcan", "--channel", "nosuchcan9"],
        ["can-sim", "--rate", "0", "--bus", "virtual"], ["can-sim", "--object-closure", "5",
                                                         "--bus", "virtual"],
        ["nosuchcommand"], ["simulate"],
    ]
    for argv in argvs:
        _cli_probe("command line", argv)
    busy.close()


def probe_quality():
    from handle_drake.geometry.quality import ContactParams, grasp_quality, quality_from_wrenches

    P = np.array([[1, 1, 1], [1, -1, -1], [-1, 1, -1], [-1, -1, 1]]) / np.sqrt(3) * 0.05
    N = -P / 0.05
    L = 0.05
    for mu in (1e5, 1e6, 1e9, 1e300, -1, float("nan"), 0.5 + 0j, "0.5", True):
        _quality_probe(lambda mu=mu: grasp_quality(P, N, ContactParams(mu=mu,
                                                   characteristic_length=L)), f"mu={mu!r}")
    for k in (0, 2, 257, 1000, 10000, 2.5, -1):
        _quality_probe(lambda k=k: grasp_quality(P, N, ContactParams(num_edges=k,
                                                 characteristic_length=L)), f"num_edges={k}")
    for scale in (1e302, 1e200, 1e-320):
        _quality_probe(lambda s=scale: grasp_quality(P * s, N, ContactParams(
            characteristic_length=L)), f"points*{scale}")
    for name, (pts, nrm) in {
        "complex points": (P * (1 + 1j), N), "complex normals": (P, N * 1j),
        "nan": (P * np.nan, N), "zero normal": (P, N * 0), "shape": (P[:, :2], N),
        "mismatch": (P, N[:2]), "empty": (P[:0], N[:0]), "text": ("abc", N),
        "ragged": ([[1, 2, 3], [1, 2]], N), "object": (np.array([None] * 12).reshape(4, 3), N),
    }.items():
        _quality_probe(lambda p=pts, n=nrm: grasp_quality(p, n, ContactParams(
            characteristic_length=L)), name)
    rng = np.random.default_rng(0)
    many = rng.normal(size=(10000, 3))
    many /= np.linalg.norm(many, axis=1, keepdims=True)
    _quality_probe(lambda: grasp_quality(many * L, -many, ContactParams(characteristic_length=L),
                                         method="drake"), "10000 contacts drake")
    for W in (np.ones((8, 6)) * 1j, np.full((8, 6), 1e300), np.full((8, 6), 1e-320),
              np.zeros((0, 6)), np.ones((8, 5))):
        _quality_probe(lambda W=W: quality_from_wrenches(W), f"wrenches {W.shape} {W.flat[:1]}")


def _quality_probe(function, name):
    try:
        with time_limit(60):
            q = function()
        wrong = not np.isfinite(q.value)
        if "mu=1e" in name or "num_edges" in name or "points*" in name:
            wrong = wrong or not q.force_closure  # closure grasp must stay closure
        record("grasp quality", "wrong" if wrong else "clean", f"{name} -> {q}")
    except Hang:
        record("grasp quality", "hang", name)
    except (ValueError, TypeError) as error:
        record("grasp quality", "clean", f"{name}: {error}")
    except BaseException as error:  # noqa: BLE001
        record("grasp quality", "traceback", f"{name}: {type(error).__name__}: {error}")


def probe_trial_log(tmp):
    from handle_drake.learning import TrialLogError
    from handle_drake.learning.log import TrialLog

    src = tmp / "log.sqlite"
    with TrialLog(src) as log:
        log.create_run("r", "random", [[0, 1], [0, 1]], 0, "objective")
        for i in range(40):
            log.add_pending("r", i, [0.5, 0.25], i, scenario="hand: {kind: shadow}\n" * 3)
            log.mark_running("r", i)
            log.mark_done("r", i, 0.1 * i, contacts={"thumb": [1, 2, 3]})
    conn = sqlite3.connect(src)
    conn.execute("PRAGMA wal_checkpoint(TRUNCATE)")
    conn.close()
    data = src.read_bytes()
    rng = random.Random(1)
    for k in range(150):
        damaged = bytearray(data)
        start = rng.randrange(100, len(damaged) - 8)
        for i in range(rng.randint(1, 8)):
            damaged[start + i] = rng.randrange(256)
        path = tmp / f"d{k}.sqlite"
        path.write_bytes(bytes(damaged))
        try:
            with time_limit(30), TrialLog(path) as log:
                for run in log.runs():
                    log.trials(run.run_id)
            outcome = "clean"  # damage in free space or text: readable
        except TrialLogError:
            outcome = "clean"
        except Hang:
            outcome = "hang"
        except BaseException as error:  # noqa: BLE001
            outcome = f"traceback {type(error).__name__}"
        if path.read_bytes() != bytes(damaged):
            outcome = "wrong"
        record("trial log", outcome.split()[0], f"scribble {k} at {start}: {outcome}")


def probe_can(tmp):
    import msgpack

    from handle_drake.devices.can_hand import protocol as P

    group = f"239.255.{random.randint(0, 255)}.{random.randint(1, 254)}"
    bus_port = random.randint(20000, 60000)
    env = dict(os.environ, PYTHONPATH=str(ROOT))
    bus = ["--bus", "udp_multicast", "--channel", group, "--bus-port", str(bus_port)]
    sim = subprocess.Popen([sys.executable, "-m", "handle_drake.devices.can_hand.cli", "can-sim",
                            "--hand", "barrett", "--rate", "200", *bus],
                           stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, env=env)
    server = subprocess.Popen([sys.executable, "-m", "handle_drake.devices.can_hand.cli",
                               "can-server",
                               "--hand", "barrett", "--listen", "127.0.0.1:0",
                               "--hello-timeout", "1", *bus],
                              stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, env=env)
    try:
        sim.stdout.readline()
        port = int(server.stdout.readline().split()[2].rsplit(":", 1)[1])
        hello = P.pack_hello(P.HandInfo("barrett", 8, 4, 3))

        def streaming():
            with socket.create_connection(("127.0.0.1", port), timeout=3) as s:
                s.sendall(hello)
                reader, n, end = P.FrameReader(), 0, time.monotonic() + 0.5
                while time.monotonic() < end:
                    s.settimeout(max(0.01, end - time.monotonic()))
                    try:
                        data = s.recv(65536)
                    except TimeoutError:
                        break
                    n += sum(t == P.STATE for t, _ in reader.feed(data))
                return n > 20

        base = dict(timestamp=0.0, arbitration_id=0x300, is_extended_id=False,
                    is_remote_frame=False, is_error_frame=False, channel=None, dlc=0, data=b"",
                    is_fd=False, bitrate_switch=False, error_state_indicator=False)
        variants = [dict(arbitration_id=v) for v in (300.5, True, -1, 2**40, "x", None, [1])]
        variants += [dict(is_fd=v) for v in ("yes", 2, None)] + [dict(data=v) for v in
                                                                ("t", 5, [300], None)]
        variants += [dict(dlc=v) for v in (99, -1, "x")] + [dict(is_error_frame=[]),
                                                           dict(channel={"a": 1}),
                                                           dict(timestamp="x"), dict(extra=1)]
        datagrams = [msgpack.packb({**base, **v}, use_bin_type=True) for v in variants]
        datagrams += [b"", b"\xff" * 4000, os.urandom(64), msgpack.packb([1, 2]),
                      msgpack.packb({"arbitration_id": 1}), b"\x00garbage" * 10]
        with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as s:
            s.setsockopt(socket.IPPROTO_IP, socket.IP_MULTICAST_IF, socket.inet_aton("127.0.0.1"))
            for datagram in datagrams:
                for _ in range(20):
                    s.sendto(datagram, (group, bus_port))
                record("CAN bus frames", _can_outcome(sim, server, streaming),
                       repr(datagram[:40]))
        tcp = [os.urandom(100), b"HC" + os.urandom(50), hello + os.urandom(200),
               hello + P.pack(P.COMMAND, os.urandom(40)), hello + P.pack(P.STATS_REQ) * 5000,
               P.pack(P.COMMAND, b"x"), hello + b"HC\x01\x07" + b"\xff" * 4,
               P.pack_hello(P.HandInfo("\udcff".encode("utf-8", "surrogatepass").decode(
                   "latin1"), 1, 1, 1)), P.pack(P.HELLO, b"\x01\x00\x01\x00\x01\x00\xff\xfe")]
        for data in tcp:
            with socket.create_connection(("127.0.0.1", port), timeout=3) as c:
                with contextlib.suppress(OSError):
                    c.sendall(data)
                time.sleep(0.05)
            record("CAN server clients", _can_outcome(sim, server, streaming), repr(data[:30]))
        idle = [socket.create_connection(("127.0.0.1", port), timeout=3) for _ in range(60)]
        time.sleep(1.5)
        record("CAN server clients", "clean" if streaming() else "traceback", "60 idle clients")
        for c in idle:
            c.close()
    finally:
        for process in (server, sim):
            process.send_signal(signal.SIGTERM)
            try:
                process.wait(5)
            except subprocess.TimeoutExpired:
                process.kill()


def _can_outcome(sim, server, streaming):
    """traceback: a process died; hang: alive but no STATE stream (retried once)."""
    if sim.poll() is not None or server.poll() is not None:
        return "traceback"
    return "clean" if streaming() or streaming() else "hang"


def _write_meshes(tmp):
    """Meshes a user would bring, good and bad (written here: no third-party files)."""
    import trimesh

    box = trimesh.creation.box((40.0, 30.0, 60.0))  # millimetres
    box.export(tmp / "box_mm.stl")
    trimesh.creation.torus(0.03, 0.01).export(tmp / "torus.obj")
    shell = trimesh.creation.icosphere(2, 0.03)
    shell.update_faces(shell.triangles_center[:, 2] < 0.01)  # a bowl-like open shell
    shell.export(tmp / "open_shell.ply")
    (tmp / "empty.stl").write_bytes(b"")
    (tmp / "garbage.stl").write_bytes(os.urandom(500))
    (tmp / "text.obj").write_text("hello world\n")
    (tmp / "nan.obj").write_text("v nan 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 3\n")
    (tmp / "line.obj").write_text("v 0 0 0\nv 1 0 0\nv 2 0 0\nf 1 2 3\n")
    (tmp / "points.ply").write_text(
        "ply\nformat ascii 1.0\nelement vertex 2\nproperty float x\nproperty float y\n"
        "property float z\nend_header\n0 0 0\n1 1 1\n")
    (tmp / "bad_index.obj").write_text("v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 99\n")
    (tmp / "mesh.txt").write_text("v 0 0 0\n")
    trimesh.creation.box((1000.0, 1000.0, 1000.0)).export(tmp / "km.stl")  # 1 km at scale 1


def probe_second_wave(tmp):
    """The second-wave surfaces: inhand, instruments, midi, perceive, mesh objects, --executor."""
    _write_meshes(tmp)
    if not (tmp / "ok.yaml").exists():
        (tmp / "ok.yaml").write_text("simulation_duration: 0.01\n")
        (tmp / "dir").mkdir()
        os.mkfifo(tmp / "fifo")
    d, fifo, ok = str(tmp / "dir"), str(tmp / "fifo"), str(tmp / "ok.yaml")
    long = "a" * 300
    (tmp / "frame.json").write_text('{"format": "handle_drake-depth-frame", "version": 1}')
    (tmp / "garbage.json").write_bytes(os.urandom(200))
    (tmp / "frame_nopng.json").write_text(json.dumps({
        "format": "handle_drake-depth-frame", "version": 1, "depth_png": "none.png",
        "depth_scale": 0.001, "width": 4, "height": 4,
        "K": [[1, 0, 2], [0, 1, 2], [0, 0, 1]], "X_WC": np.eye(4).tolist()}))
    (tmp / "mapping.yaml").write_text("controls: 5\n")
    (tmp / "mapping_dup.yaml").write_text("port_name: a\nport_name: b\n")
    mesh_scn = tmp / "mesh_scn.yaml"
    dsec = ["--executor", "dask://127.0.0.1:1", "--connect-timeout", "1"]
    argvs = {
        "inhand": [
            ["--trials", "0"], ["--trials", "-1"], ["--trials", "big"], ["--trials", "1e9"],
            ["--workers", "0"], ["--workers", "100000"], ["--particles", "0"],
            ["--particles", "1e9"], ["--particles", "1000000"], ["--target-deg", "-5"],
            ["--target-deg", "nan"], ["--target-deg", "1000"], ["--accelerometer", "nope"],
            ["--seed", "-1"], ["--seed", "1e300"], ["--db", d], ["--db", fifo], ["--db", ok],
            ["--db", f"{ok}/x.sqlite"], ["--db", f"{tmp}/{long}.sqlite"], ["--plot", d],
            ["--html", d], ["--connect-timeout", "-1"], ["--connect-timeout", "nan"],
            ["--connect-timeout", "1e9"], ["--executor", "ftp://x"],
            ["--executor", "dask://HOST:PORT"], ["--executor", "dask://:"], dsec,
            ["--task", "nope"], ["--optimizer", "nope"], ["--evaluation", "nope"]],
        "instruments": [
            ["--device", "nope"], ["--seed", "-1"], ["--seed", "x"], ["--plot", d],
            ["--json", d], ["--html", d], ["--plot", f"{ok}/x.png"], ["--json", f"{ok}/x.json"],
            ["--write-scenarios", ok], ["--write-scenarios", f"{ok}/sub"],
            ["--plot", f"{tmp}/{long}.png"]],
        "midi": [
            ["jog", "--html", d], ["jog", "--scenario", d], ["jog", "--scenario", fifo],
            ["jog", "--scenario", str(tmp / "missing.yaml")], ["fader", "--override", "driver: 5"],
            ["fader", "--override", "midi_controller: null"], ["jog", "--override", "!Foo {}"],
            ["control", "--mapping", d], ["control", "--mapping", str(tmp / "mapping.yaml")],
            ["control", "--mapping", str(tmp / "mapping_dup.yaml")],
            ["control", "--mapping", str(tmp / "garbage.stl")],
            ["control", "--duration", "-1"], ["control", "--duration", "1e300"],
            ["control", "--duration", "nan"], ["control", "--hardware", "--duration", "0.1"],
            ["control", "--port", "nope", "--duration", "0.1"],
            ["monitor", "--duration", "-1"], ["monitor", "--mapping", fifo],
            ["monitor", "--port", "nope", "--duration", "0.1"],
            ["write-scenarios", ok], ["write-scenarios", f"{ok}/x"], ["nope"]],
        "perceive": [
            [ok], [d], [fifo], ["--frame", d], ["--frame", fifo],
            ["--frame", str(tmp / "missing.json")], ["--frame", str(tmp / "garbage.json")],
            ["--frame", str(tmp / "frame.json")], ["--frame", str(tmp / "frame_nopng.json")],
            ["--frame", str(tmp / "box_mm.stl")],
            ["diagrams/tabletop_perception.yaml", "--save-frames", ok],
            ["diagrams/tabletop_perception.yaml", "--override", "cameras: 5"],
            ["diagrams/tabletop_perception.yaml", "--override",
             "cameras: [{profile: nope, config: {name: k}}]"],
            ["diagrams/tabletop_perception.yaml", "--override",
             "cameras: [{config: {name: k, X_PB: {base_frame: nowhere}}}]"],
            ["diagrams/tabletop_perception.yaml", "--override",
             "cameras: [{config: {name: k, width: 1000000000}}]"],
            ["diagrams/tabletop_perception.yaml", "--override",
             "cameras: [{target: [0, 0, 0], config: {name: k, X_PB: {translation: [0, 0, 0]}}}]"],
            ["diagrams/tabletop_perception.yaml", "--override",
             "cameras: [{target: [0, 0, 0], "
             "config: {name: k, X_PB: {translation: [-0.7, 0, 0.7]}}}, {target: [0, 0, 0], "
             "config: {name: k, X_PB: {translation: [0.7, 0, 0.7]}}}]"],
            []],
        "mesh objects": [
            *[[c, "--mesh", str(tmp / f)] for c in ("grasp --class tripod", "babble --trials 1")
              for f in ("missing.stl", "dir", "fifo", "empty.stl", "garbage.stl", "text.obj",
                        "nan.obj", "line.obj", "points.ply", "bad_index.obj", "mesh.txt",
                        "km.stl")],
            ["grasp --class tripod", "--mesh", str(tmp / "box_mm.stl"), "--mesh-scale", "0"],
            ["grasp --class tripod", "--mesh", str(tmp / "box_mm.stl"), "--mesh-scale", "-1"],
            ["grasp --class tripod", "--mesh", str(tmp / "box_mm.stl"), "--mesh-scale", "nan"],
            ["grasp --class tripod", "--mesh", str(tmp / "box_mm.stl"), "--mesh-scale", "1e300"],
            ["grasp --class tripod", "--mesh", str(tmp / "box_mm.stl"), "--mesh-scale", "1e-300"],
            ["grasp --class tripod", "--mesh", str(tmp / "box_mm.stl"), "--mesh-scale", "0.001",
             "--mass", "-1"],
            ["grasp --class tripod", "--mesh", str(tmp / "box_mm.stl"), "--mesh-scale", "0.001",
             "--mass", "1e30"],
            ["grasp --class tripod", "--mesh-scale", "0.001"],
            ["grasp --class tripod", "--mass", "2", "--size", "0.05"],
            ["babble", "--mesh-scale", "0.001"],
            ["babble", "--mesh", str(tmp / "box_mm.stl"), "--object", "mug"],
            ["grasp --class tripod", "--mesh", str(tmp / "box_mm.stl"), "--object", "sphere"],
            ["report --reduced", "--mesh", str(tmp / "missing.stl")],
            ["report --reduced", "--mesh", str(tmp / "km.stl")],
            *[["simulate", str(mesh_scn), "--override", o] for o in (
                "object: {kind: mesh}", "object: {kind: mesh, file: 5}",
                "object: {kind: mesh, file: empty.stl}", "object: {kind: mesh, file: dir}",
                "object: {kind: mesh, file: box_mm.stl, scale: -1}",
                "object: {kind: mesh, file: box_mm.stl, scale: 0.001, mass: 0}",
                "object: {kind: mesh, file: box_mm.stl, scale: 0.001, density: -1}",
                "object: {kind: mesh, file: box_mm.stl, scale: 0.001, mass: 1, density: 1}",
                "object: {kind: mesh, file: box_mm.stl, scale: 0.001, size: 2}",
                "object: {kind: mesh, file: box_mm.stl, scale: 0.001, nope: 2}",
                "object: {kind: mesh, file: box_mm.stl, scale: [1, 2]}",
                "object: {kind: sphere, file: box_mm.stl}")],
            ["perceive", str(mesh_scn), "--override",
             "object: {kind: mesh, file: garbage.stl}"]],
        "executor": [
            ["babble", "--trials", "2", *dsec], ["babble", "--executor", "nope"],
            ["babble", "--executor", "dask", "--workers", "0"],
            ["babble", "--executor", "dask", "--workers", "100000"],
            ["babble", "--executor", "dask://", "--trials", "2"],
            ["babble", "--executor", "dask://256.1.1.1:8786", "--connect-timeout", "1"],
            ["babble", "--executor", "dask://127.0.0.1:99999", "--connect-timeout", "1"],
            ["report", "--reduced", *dsec], ["report", "--workers", "-1"],
            ["inhand", "--trials", "2", *dsec]],
    }
    mesh_scn.write_text("simulation_duration: 0.01\n")
    for part, cases in argvs.items():
        for case in cases:
            argv = case
            if part in ("inhand", "instruments", "midi", "perceive"):
                argv = [part, *case]
            if argv and " " in argv[0]:
                argv = argv[0].split() + argv[1:]
            _cli_probe(part, argv, cwd=tmp if "simulate" in argv or "perceive" in argv else None,
                       warned=any("size: 2" in a for a in argv))  # a warning is the answer


def _cli_probe(part, argv, cwd=None, limit=120, warned=False):
    """Runs ``handle-drake argv``: clean is exit 2 with a short message (or, where
    ``warned``, exit 0 with a one-line warning)."""
    from handle_drake.cli import main

    err, here = io.StringIO(), os.getcwd()
    if cwd is not None and argv[1:2] != ["diagrams/tabletop_perception.yaml"]:
        os.chdir(cwd)
    try:
        with time_limit(limit), contextlib.redirect_stderr(err), \
                contextlib.redirect_stdout(io.StringIO()):
            try:
                code = main(argv)
            except SystemExit as exit_:
                code = exit_.code
    except Hang:
        record(part, "hang", " ".join(argv))
        return
    except BaseException as error:  # noqa: BLE001
        record(part, "traceback", f"{' '.join(argv)}: {type(error).__name__}: {error}"[:300])
        return
    finally:
        os.chdir(here)
    text = err.getvalue()
    if "Traceback" in text:
        record(part, "traceback", f"{' '.join(argv)}: {text[-300:]}")
    elif (code == 2 or (warned and code == 0 and "warning:" in text)) and len(text) < 2000:
        record(part, "clean", f"{' '.join(argv)} -> {text.strip()[:200]}")
        if os.environ.get("PROBE_VERBOSE"):
            print(f"  clean {part}: {' '.join(argv)[-80:]} -> {text.strip()[:160]}",
                  file=sys.stderr)
    else:
        record(part, "wrong", f"{' '.join(argv)} -> exit {code} {text[-200:]!r}")


# ------------------------------------------------------------------ third wave (issue 31)
def _forked(limit, function):
    """Runs ``function() -> (outcome, text)`` in a forked child: ('hang', ...) when it
    has not answered within ``limit`` s (the child is killed: numpy or Dask stuck in C
    cannot be interrupted by an alarm), ('traceback', ...) when it died."""
    import select

    read, write = os.pipe()
    pid = os.fork()
    if pid == 0:  # the child
        os.close(read)
        try:
            outcome = function()
        except BaseException as error:  # noqa: BLE001
            outcome = ("traceback", f"{type(error).__name__}: {error}"[:300])
        os.write(write, json.dumps(outcome).encode()[:60000])
        os._exit(0)
    os.close(write)
    ready, _, _ = select.select([read], [], [], limit)
    try:
        if not ready:
            os.kill(pid, signal.SIGKILL)
            return "hang", f"no answer within {limit} s"
        data = b""
        while chunk := os.read(read, 65536):
            data += chunk
        return tuple(json.loads(data)) if data else ("traceback", "the child died")
    finally:
        os.close(read)
        os.waitpid(pid, 0)


def _api(words, call):
    """A probe body: clean when ``call`` raises ValueError/TypeError/FileNotFoundError
    with one line holding ``words``; wrong when it returns (a silent accept)."""
    def body():
        try:
            with contextlib.redirect_stderr(io.StringIO()), \
                    contextlib.redirect_stdout(io.StringIO()):
                call()
        except (ValueError, TypeError, FileNotFoundError) as error:
            text = str(error)
            ok = all(w in text for w in words) and "\n" not in text.strip()
            return ("clean" if ok else "wrong", f"{type(error).__name__}: {text}"[:300])
        return "wrong", "accepted"
    return body


BASELINE = {"s": 0.0}  # s: a command refused before any work, on this machine now


def _cmd(argv, words, cwd=None, quick=None, absent=(), one_line=False):
    """A probe body: ``handle-drake argv`` must exit 2 with one line naming ``words``,
    within ``quick`` s (plus the run's :data:`BASELINE`: the machine is shared and its
    speed changes) if given, leaving the ``absent`` paths unwritten. ``one_line``: the
    message after "error:" holds no line break (argparse's usage lines come before it)."""
    def body():
        from handle_drake.cli import main

        if cwd is not None:
            os.chdir(cwd)
        err = io.StringIO()
        start = time.monotonic()
        with contextlib.redirect_stderr(err), contextlib.redirect_stdout(io.StringIO()):
            try:
                code = main(argv)
            except SystemExit as exit_:
                code = exit_.code
        took, text = time.monotonic() - start, err.getvalue()
        if "Traceback" in text:
            return "traceback", text[-300:]
        written = [str(p) for p in absent if Path(p).exists()]
        message = text.split("error:", 1)[-1].strip()
        ok = (code == 2 and all(w in text for w in words) and len(text) < 2000
              and not (one_line and "\n" in message)
              and (quick is None or took < quick + BASELINE["s"]) and not written)
        return ("clean" if ok else "wrong",
                f"exit {code} in {took:.1f} s, wrote {written}: {text.strip()[-200:]}")
    return body


def _listen(kind):
    server = socket.socket()
    server.bind(("127.0.0.1", 0))
    server.listen(64)
    payload = {"silent": b"", "one": b"\x01", "garbage": bytes(range(256)) * 4, "close": None,
               "http": b"HTTP/1.1 400 Bad Request\r\nContent-Length: 0\r\n\r\n"}[kind]
    held = []

    def serve():
        import threading  # noqa: F401

        while True:
            try:
                conn, _ = server.accept()
            except OSError:
                return
            if payload is None:
                conn.close()
                continue
            held.append(conn)
            if payload:
                try:
                    conn.sendall(payload)
                except OSError:
                    pass

    import threading

    threading.Thread(target=serve, daemon=True).start()
    return server, held


def _frames(tmp):
    from PIL import Image

    from handle_drake.devices.camera.frames import DepthFrame, save_frame

    folder = tmp / "frames"
    folder.mkdir(exist_ok=True)
    base = save_frame(folder / "ok", DepthFrame(np.full((48, 64), 0.8),
                                                [[60.0, 0, 32], [0, 60.0, 24], [0, 0, 1]],
                                                np.eye(4)))
    good = json.loads(base.read_text())
    cases = {}

    def sidecar(name, png=None, **changes):
        meta = dict(good, **changes)
        if png is not None:
            meta["depth_png"] = png
        path = folder / f"{name}.json"
        path.write_text(json.dumps(meta))
        cases[name] = path

    for name, changes in {
            "fx_tiny": {"K": [[1e-300, 0, 32], [0, 60, 24], [0, 0, 1]]},
            "fx_huge": {"K": [[1e300, 0, 32], [0, 60, 24], [0, 0, 1]]},
            "fy_zero": {"K": [[60, 0, 32], [0, 0, 24], [0, 0, 1]]},
            "cx_far": {"K": [[60, 0, 1e12], [0, 60, 24], [0, 0, 1]]},
            "cy_negative": {"K": [[60, 0, 32], [0, 60, -500], [0, 0, 1]]},
            "K_last_row": {"K": [[60, 0, 32], [0, 60, 24], [1, 1, 1]]},
            "pose_last_row": {"X_WC": [[1, 0, 0, 0], [0, 1, 0, 0], [0, 0, 1, 0], [5, 5, 5, 5]]},
            "pose_far": {"X_WC": [[1, 0, 0, 1e9], [0, 1, 0, 0], [0, 0, 1, 0], [0, 0, 0, 1]]},
            "pose_text": {"X_WC": "junk"},
            "pose_scaled": {"X_WC": (np.eye(4) * 2).tolist()},
            "scale_true": {"depth_scale": True}, "scale_text": {"depth_scale": "0.001"},
            "scale_huge": {"depth_scale": 1e300}, "scale_tiny": {"depth_scale": 1e-300},
            "version_99": {"version": 99}, "version_text": {"version": "1"},
            "width_text": {"width": "64"}, "height_float": {"height": 48.0},
            "width_huge": {"width": 12000, "height": 9000},
            "png_list": {"depth_png": ["ok.png"]}}.items():
        sidecar(name, **changes)
    Image.fromarray(np.full((48, 64), 200, np.uint8)).save(folder / "eight.png")
    sidecar("png_8bit", png="eight.png")
    Image.fromarray(np.full((48, 64), -99_999_999, np.int32)).save(folder / "tiff.png",
                                                                    format="TIFF")
    sidecar("tiff_as_png", png="tiff.png")
    Image.fromarray(np.zeros((48, 64, 3), np.uint8)).save(folder / "rgb.png")
    sidecar("png_rgb", png="rgb.png")
    import zlib

    def chunk(kind, data):
        return len(data).to_bytes(4, "big") + kind + data + zlib.crc32(kind + data).to_bytes(
            4, "big")

    (folder / "huge.png").write_bytes(
        b"\x89PNG\r\n\x1a\n" + chunk(b"IHDR", (12000).to_bytes(4, "big")
                                     + (9000).to_bytes(4, "big") + bytes([16, 0, 0, 0, 0]))
        + chunk(b"IDAT", zlib.compress(b"")) + chunk(b"IEND", b""))
    sidecar("png_108mpx_header", png="huge.png", width=12000, height=9000)
    words = {"fx_tiny": "fx", "fx_huge": "fx", "fy_zero": "fy", "cx_far": "cx",
             "cy_negative": "cy", "K_last_row": "K", "pose_last_row": "X_WC",
             "pose_far": "X_WC", "pose_text": "X_WC", "pose_scaled": "X_WC",
             "png_list": "depth_png", "png_8bit": "16-bit", "tiff_as_png": "PNG",
             "png_rgb": "16-bit", "png_108mpx_header": "pixels"}
    return {name: (path, words.get(name, name.split("_")[0].replace("scale", "depth_scale")))
            for name, path in cases.items()}


def probe_third_wave(tmp):
    """Issue 31's surfaces: dask:// listeners, glove files, depth frames, accelerometer,
    meshes, MIDI mappings, output paths, kill -9 of a pool's parent, messages."""
    import handle_drake.cli  # noqa: F401 - loaded once, before the forks
    from handle_drake.apps.inhand.glove import GLOVE_SENSORS, load_glove
    from handle_drake.scenario import LoadScenario

    tmp = Path(tmp)
    (tmp / "dir").mkdir(exist_ok=True)
    if not (tmp / "fifo").exists():
        os.mkfifo(tmp / "fifo")
    cases = []  # (part, name, limit, body)

    def baseline():  # refused by the output check, before any work, on every version
        start = time.monotonic()
        _cmd(["babble", "--db", str(tmp / "dir"), "--trials", "1"], [])()
        return "clean", str(time.monotonic() - start)
    BASELINE["s"] = max(float(_forked(120, baseline)[1]) for _ in range(2))
    print(f"baseline (a command refused before work): {BASELINE['s']:.1f} s", file=sys.stderr)

    # --executor dask:// against hostile local listeners
    servers = []
    for kind in ("silent", "one", "garbage", "http", "close"):
        server, held = _listen(kind)
        servers.append((server, held))
        address = f"dask://127.0.0.1:{server.getsockname()[1]}"
        db = tmp / f"dask_{kind}.sqlite"
        cases.append(("dask address", f"babble {kind}", 20, _cmd(
            ["babble", "--executor", address, "--connect-timeout", "2", "--trials", "1",
             "--db", str(db), "--no-plot", "--no-progress"], ["dask://"], quick=6,
            absent=[db])))
        cases.append(("dask address", f"inhand {kind}", 20, _cmd(
            ["inhand", "--executor", address, "--connect-timeout", "2", "--trials", "1",
             "--db", str(tmp / f"inhand_{kind}.sqlite"), "--no-plot", "--no-html",
             "--no-progress"], ["dask://"], quick=6)))

        def api(address=address):
            from handle_drake.learning.cluster import ExecutorError, trial_executor

            start = time.monotonic()
            try:
                with trial_executor(address, connect_timeout=2.0):
                    return "wrong", "connected"
            except ExecutorError as error:
                took = time.monotonic() - start
                return ("clean" if took < 6 and "\n" not in str(error) else "wrong",
                        f"{took:.1f} s: {error}"[:300])
        cases.append(("dask address", f"API {kind}", 20, api))
    for command in (["babble", "--trials", "1", "--no-plot", "--no-progress"],
                    ["inhand", "--trials", "1", "--no-plot", "--no-html", "--no-progress"]):
        cases.append(("dask address", f"{command[0]} --connect-timeout without dask://", 120,
                      _cmd([*command, "--connect-timeout", "3", "--db",
                            str(tmp / f"{command[0]}_ct.sqlite")], ["--connect-timeout"],
                           quick=6)))

    # glove recordings: loaded, then mapped and segmented as an in-hand task does
    def glove_case(name, time_stamps=None, raw=None, words=("time",), **fields):
        n = len(time_stamps) if isinstance(time_stamps, list) else 50
        document = {"format": "handle_drake.glove", "version": 1,
                    "sensors": list(GLOVE_SENSORS),
                    "time": time_stamps if time_stamps is not None else
                    [i * 0.01 for i in range(n)],
                    "raw": raw if raw is not None else [[0.1 * (i % 7)] * 22 for i in range(n)],
                    "calibration": None, "meta": {}, **fields}
        path = tmp / f"glove_{name}.json"
        path.write_text(json.dumps(document))

        def use():
            from handle_drake.apps.inhand.gist import extract_gist
            from handle_drake.apps.inhand.mapping import glove_to_shadow

            recording = load_glove(path)
            extract_gist(recording.time, glove_to_shadow(recording))
        cases.append(("glove recordings", name, 20, _api(list(words), use)))

    for step in (1e-9, 1e-12, 1e-6, 1e-5):
        glove_case(f"step {step:g}", [i * step for i in range(50)])
    glove_case("time as strings", [str(i * 0.01) for i in range(50)])
    glove_case("raw as strings", raw=[[str(0.1)] * 22] * 50, words=("raw",))
    glove_case("time booleans", [False, True] + [i * 0.01 + 2 for i in range(48)])
    glove_case("raw booleans", raw=[[True] * 22] * 50, words=("raw",))
    glove_case("time mixed text", [0, "0.01"] + [i * 0.01 + 1 for i in range(48)])
    glove_case("one sample", [0.0], raw=[[0.0] * 22])
    glove_case("time decreasing", [1.0 - i * 0.01 for i in range(50)])
    glove_case("raw nested", raw=[[[0.0]] * 22] * 50, words=("raw",))

    # perceive --frame: sidecars and images
    for name, (path, word) in _frames(tmp).items():
        cases.append(("perceive --frame", name, 60,
                      _cmd(["perceive", "--frame", str(path)], [word], cwd=tmp)))

    # accelerometer: evdev paths, recordings, estimator thresholds
    from handle_drake.devices.accelerometer import evdev_driver

    binary = tmp / "binary.rec"
    binary.write_bytes(os.urandom(300) + b"\xff\xfe")
    for device in ("/dev/zero", "/dev/null", str(tmp / "dir"), str(binary)):
        cases.append(("accelerometer", f"evdev_device {Path(device).name}", 20,
                      _api(["evdev_device"], lambda d=device: evdev_driver.open_device(d))))
    for name, path, word in (("binary", binary, "UTF-8"), ("directory", tmp / "dir",
                                                            "directory"),
                             ("FIFO", tmp / "fifo", "FIFO"), ("/dev/zero", "/dev/zero",
                                                             "device")):
        cases.append(("accelerometer", f"recording: {name}", 20,
                      _api([word], lambda p=path: evdev_driver.load_events(p))))
    for key, value in (("free_fall_threshold", "1e300"), ("free_fall_threshold", "1.5"),
                       ("window", "1e9"), ("slip_angle_tol", "100"),
                       ("rest_norm_tol", "1e300"), ("settle_time", "1e12")):
        text = f"object: {{accelerometer: {{estimators: {{{key}: {value}}}}}}}"
        cases.append(("accelerometer", f"{key}: {value}", 20,
                      _api([key], lambda t=text: LoadScenario(data=t))))

    # meshes
    import trimesh

    from handle_drake.geometry.objects.mesh import MeshObjectSpec

    box = trimesh.creation.box((0.05, 0.05, 0.05))
    lines = [f"v {x} {y} {z}" for x, y, z in box.vertices]
    for name, mutate in (("face index 0", lambda f: f.replace("f 1 ", "f 0 ", 1)),
                         ("face index 0/0", lambda f: f.replace("f 1 ", "f 0/0/0 ", 1)),
                         ("face index -0", lambda f: f.replace("f 1 ", "f -0 ", 1))):
        faces = "\n".join(f"f {a} {b} {c}" for a, b, c in box.faces + 1)
        path = tmp / f"{name.replace(' ', '_').replace('/', '_')}.obj"
        path.write_text("\n".join(lines) + "\n" + mutate(faces) + "\n")
        cases.append(("meshes", name, 60,
                      _api(["face index 0"], lambda p=path: MeshObjectSpec(file=str(p)))))
    big = tmp / "big_sphere.stl"
    trimesh.creation.icosphere(subdivisions=7, radius=0.04).export(big)  # 327,680 triangles
    cases.append(("meshes", "327k triangles", 120,
                  _api(["triangles"], lambda: MeshObjectSpec(file=str(big)))))

    # MIDI mappings naming controls the modelled device lacks
    for name, controls in (("unknown name", "[{name: slider1, kind: fader, number: 1}]"),
                           ("wrong kind", "[{name: jog, kind: fader, number: 60}]"),
                           ("button as knob", "[{name: mode, kind: knob, number: 84}]"),
                           ("some unknown", "[{name: fader1, kind: fader, number: 20}, "
                                            "{name: pad1, kind: button, number: 30}]")):
        path = tmp / f"mapping_{name.replace(' ', '_')}.yaml"
        path.write_text(f"controls: {controls}\n")
        cases.append(("MIDI mappings", name, 60, _api(
            ["controls"], lambda p=path: LoadScenario(data=f"midi_controller: {{mapping: {p}}}"))))

    # output paths: refused naming the option before any work (root passes os.access)
    for argv in (["babble", "--trials", "1", "--plot", "/proc/x.png", "--db",
                  str(tmp / "o.sqlite"), "--no-progress"],
                 ["babble", "--trials", "1", "--db", "/proc/x.sqlite", "--no-progress"],
                 ["instruments", "--quick", "--plot", "/proc/x.png"],
                 ["instruments", "--quick", "--json", "/proc/x.json"],
                 ["inhand", "--trials", "1", "--html", "/proc/x.html", "--db",
                  str(tmp / "o2.sqlite"), "--no-progress"],
                 ["inhand", "--trials", "1", "--plot", "/proc/x.png", "--db",
                  str(tmp / "o3.sqlite"), "--no-progress"],
                 ["perceive", "--frame", str(tmp / "frames" / "ok.json"), "--save-frames",
                  "/proc/frames"],
                 ["grasp", "--class", "tripod", "--size", "0.05", "--save-scenario",
                  "/proc/s.yaml"],
                 ["demo", "--html", "/proc/demo.html"]):
        option = next(a for a, b in zip(argv, argv[1:], strict=False) if b.startswith("/proc"))
        cases.append(("output paths", " ".join(argv[:1] + [option]), 120,
                      _cmd(argv, [option], quick=5)))

    # messages
    comment = tmp / "comment.yaml"
    comment.write_text("# nothing here yet\n")
    for name, body in (
            ("babble --size 1e300", _cmd(["babble", "--size", "1e300", "--trials", "1",
                                          "--no-plot", "--no-progress", "--db",
                                          str(tmp / "m.sqlite")], ["size"], quick=6)),
            ("babble --run-id ''", _cmd(["babble", "--run-id", "", "--trials", "1", "--no-plot",
                                         "--no-progress", "--db", str(tmp / "m2.sqlite")],
                                        ["--run-id"], quick=6)),
            ("can-server --channel ''", _cmd(["can-server", "--channel", ""], ["--channel"],
                                             quick=6)),
            ("NaN rotation", _api(["rotation"], lambda: LoadScenario(
                data="object: {X_WO: {rotation: !Rpy {deg: [.nan, 0, 0]}}}"))),
            ("NaN axis", _api(["rotation.axis"], lambda: LoadScenario(
                data="hand: {mount: !FixedMount {X_WB: {rotation: !AngleAxis "
                     "{angle_deg: 3, axis: [.nan, 0, 1]}}}}"))),
            ("port 0", _api(["1..65535"], lambda: LoadScenario(
                data="driver: !CanHandDriver {port: 0}")))):
        cases.append(("messages", name, 15 if "can-server" in name else 60, body))

    def comment_only():  # as an empty file: the defaults
        try:
            LoadScenario(filename=comment)
        except ValueError as error:
            return "wrong", str(error)[:300]
        return "clean", "loaded as empty"
    cases.append(("messages", "comment-only scenario", 60, comment_only))

    only = os.environ.get("PROBE_ONLY")
    for part, name, limit, body in cases:
        if only and only not in part:
            continue
        outcome, text = _forked(limit, body)
        record(part, outcome, f"{name}: {text}")
        if os.environ.get("PROBE_VERBOSE"):
            print(f"  {outcome:9} {part}: {name}: {text[:150]}", file=sys.stderr)
    for server, held in servers:
        server.close()
        for conn in held:
            conn.close()
    if not only or "kill" in only or "ctrl" in only:
        _probe_kill_9(tmp)
        _probe_ctrl_c(tmp)


def probe_fourth_wave(tmp, only=None):
    """Issue 46's surfaces: pick's targets, hands, scenes and grasp database, the in-hand
    options, seeds, numba's cache, trial logs; then three process checks (two runs on one
    log, kill -9 and resume, SIGINT and resume). ``only``: a surface name's part."""
    import handle_drake.cli  # noqa: F401 - loaded once, before the forks

    tmp = Path(tmp)
    only = only or os.environ.get("PROBE_ONLY")
    (tmp / "dir").mkdir(exist_ok=True)
    if not (tmp / "fifo").exists():
        os.mkfifo(tmp / "fifo")
    H = str(ROOT / "diagrams" / "hamburg_setup.yaml")
    cases = []  # (part, name, limit, body, accepted_if_slow)

    def pick(name, override, words, part="pick scenes", extra=(), limit=60):
        argv = ["pick", H, "--true-poses", *extra] + (["--override", override] if override
                                                        else [])
        cases.append((part, name, limit, _cmd(argv, words, cwd=tmp, quick=10, one_line=True,
                                               absent=[tmp / "out.png"]), True))

    # pick: targets and hands
    pick("--kind without a hole", "sorting_box: {holes: [{kind: cylinder, size: 0.05}]}",
         ["--kind"], "pick targets", ["--kind", "sphere"])
    pick("--html out.png", None, ["--html"], "pick targets", ["--html", str(tmp / "out.png")])
    pick("Barrett hand on the arm", "hand: {kind: barrett, coupling_ratio: null}",
         ["hand.kind"], "pick targets")
    # pick: scenes
    arm = "hand: {mount: !Arm {kind: pa10, X_WB: {translation: %s}%s}}"
    pick("X_FH NaN rotation", arm % ("[-1.0, 0, 0]", ", X_FH: {rotation: !Rpy {deg: [.nan, 0, "
                                                      "0]}}"), ["X_FH"])
    pick("sorting box at NaN", "sorting_box: {X_WB: {translation: [.nan, 0.3, 0]}}",
         ["sorting_box.X_WB"])
    pick("arm base inside the table", arm % ("[0, 0, -0.2]", ""), ["hand.mount.X_WB"])
    pick("arm base 5 m below", arm % ("[-1.0, 0, -5]", ""), ["hand.mount.X_WB"])
    pick("object at [3, 3, 0]", "object: {kind: sphere, size: 0.06, X_WO: {translation: "
                                "[3, 3, 0]}}", ["object.X_WO"])
    pick("sorting box floating", "sorting_box: {on_table: false, X_WB: {translation: "
                                 "[0.0, 0.3, 0.5]}}", ["sorting_box"])
    pick("sorting box beside the table", "sorting_box: {X_WB: {translation: [0.0, 1.5, 0]}}",
         ["sorting_box"])
    pick("coupling ratio 100", "hand: {coupling_ratio: 100}", ["coupling_ratio"])

    # pick: the grasp database
    shipped = json.loads((ROOT / "handle_drake" / "apps" / "pick" / "data" /
                          "grasp_database.json").read_text())
    grasped = next(i for i, e in enumerate(shipped["entries"]) if e["grasp"] is not None)

    def database(name, change=None, raw=None):
        path = tmp / f"db_{name}.json"
        if raw is not None:
            path.write_bytes(raw)
        else:
            data = json.loads(json.dumps(shipped))
            change(data)
            path.write_text(json.dumps(data))
        return path

    def entry(field, value):
        def change(data):
            data["entries"][grasped]["grasp"][field] = value
        return change

    zero = [[0.0] * 4 for _ in range(4)]
    nan = np.eye(4).tolist()
    nan[0][3] = float("nan")  # json writes NaN, which Python reads back
    mirrored = np.diag([1.0, 1.0, -1.0, 1.0]).tolist()
    for name, path, words in (
            ("FIFO", tmp / "fifo", ["fifo"]), ("/dev/zero", Path("/dev/zero"), ["/dev/zero"]),
            ("directory", tmp / "dir", ["dir"]),
            ("binary", database("binary", raw=zlib.compress(json.dumps(shipped).encode())),
             ["db_binary.json"]),
            ("entries: 5", database("entries5", lambda d: d.update(entries=5)), ["entries"]),
            ("entry a number", database("entry5", lambda d: d.update(entries=[5])),
             ["entries[0]"]),
            ("NaN X_PG", database("nan", entry("X_PG", nan)), ["X_PG"]),
            ("all-zero X_BP", database("zero", entry("X_BP", zero)), ["X_BP"]),
            ("mirrored X_PG", database("mirror", entry("X_PG", mirrored)), ["X_PG"]),
            ("NaN contact_error", database("nanerr", entry("contact_error", float("nan"))),
             ["contact_error"])):
        cases.append(("grasp database", f"--grasp-db {name}", 60, _memory_capped(_cmd(
            ["pick", H, "--true-poses", "--grasp-db", str(path)], words, cwd=tmp, quick=10,
            one_line=True)),
            name not in ("FIFO", "/dev/zero")))  # no answer from reading those: a hang
    cases.append(("grasp database", "--build-grasp-db to /proc", 90, _cmd(
        ["pick", H, "--true-poses", "--build-grasp-db", "--grasp-db", "/proc/x.json"],
        ["--grasp-db"], cwd=tmp, quick=10, one_line=True), True))

    # inhand: every refusal before the trial log exists, every option bounded
    for name, argv, words in (
            ("--placement regrasp", ["--placement", "regrasp"], ["--placement"]),
            ("--grip-digits 6", ["--task", "screw_cap", "--grip-digits", "6"],
             ["--grip-digits"]),
            ("jog_wheel --gaits 2", ["--task", "jog_wheel", "--gaits", "2"], ["--gaits"]),
            ("--target-deg 1e308", ["--target-deg", "1e308"], ["--target-deg"]),
            ("--target-deg -90", ["--target-deg", "-90"], ["--target-deg", "(0, 360]"]),
            ("--particles 1e9", ["--particles", "1000000000"], ["--particles"]),
            ("--gaits 1000000", ["--task", "screw_cap", "--gaits", "1000000"], ["--gaits"]),
            ("--trials 1e12", ["--trials", "1000000000000"], ["--trials"]),
            ("--workers 1e6", ["--workers", "1000000"], ["--workers"]),
            ("--seed 2**70", ["--seed", str(2**70)], ["--seed"])):
        db = tmp / f"inhand_{len(cases)}.sqlite"
        cases.append(("inhand options", name, 60, _cmd(
            ["inhand", "--trials", "1", "--no-progress", "--db", str(db), *argv], words,
            quick=10, one_line=True, absent=[db]), "--gaits 1" not in name))  # 1e6 gaits: a hang
    db = tmp / "babble_seed.sqlite"
    cases.append(("inhand options", "babble --seed 2**70", 60, _cmd(
        ["babble", "--trials", "1", "--no-progress", "--no-plot", "--seed", str(2**70),
         "--db", str(db)], ["--seed"], quick=10, one_line=True, absent=[db]), True))

    # messages
    cases.append(("messages", "--chunk ²", 30, _cmd(
        ["babble", "--chunk", "²", "--trials", "1", "--db", str(tmp / "c.sqlite")],
        ["--chunk", "'²'", "integer"], quick=10, one_line=True), True))
    bad_log = _log_with_bad_scenario(tmp) if not only or "messages" in only else None
    cases.append(("messages", "trial log: scenario not UTF-8", 60, _cmd(
        ["babble", "--strategy", "random", "--trials", "2", "--no-plot", "--no-progress",
         "--db", str(bad_log)], ["scenario", "UTF-8"], quick=10, one_line=True), False))
    cases.append(("messages", "numba: no cache locator", 120, _no_cache_locator, False))

    def baseline():  # refused by the output check, before any work, on every version
        start = time.monotonic()
        _cmd(["pick", H, "--true-poses", "--html", str(tmp / "dir")], [])()
        return "clean", f"{time.monotonic() - start:.2f}"

    BASELINE["s"] = max(float(_forked(120, baseline)[1]) for _ in range(2))
    print(f"baseline (a command refused before work): {BASELINE['s']:.1f} s", file=sys.stderr)
    for part, name, limit, body, accepted_if_slow in cases:
        if only and only not in part:
            continue
        outcome, text = _forked(limit, body)
        if outcome == "hang" and accepted_if_slow:  # accepted: still working at the limit
            outcome, text = "wrong", f"accepted: still working after {limit} s"
        record(part, outcome, f"{name}: {text}")
        if os.environ.get("PROBE_VERBOSE"):
            print(f"  {outcome:9} {part}: {name}: {text[:150]}", file=sys.stderr)
    if not only or "process" in only:
        _probe_two_runs(tmp)
        _probe_kill_and_resume(tmp, "kill -9")
        _probe_kill_and_resume(tmp, "SIGINT")


def _memory_capped(body, gib=6):
    """``body`` with its address space capped (a /dev/zero read grows until MemoryError:
    on a shared machine, not with the whole of its memory)."""
    def capped():
        import resource

        resource.setrlimit(resource.RLIMIT_AS, (gib << 30, gib << 30))
        return body()
    return capped


def _babble(db, trials, **popen):
    env = dict(os.environ, PYTHONPATH=os.pathsep.join(p for p in sys.path if p),
               OPENBLAS_NUM_THREADS="1")
    return subprocess.Popen(
        [sys.executable, "-m", "handle_drake.cli", "babble", "--strategy", "random",
         "--trials", str(trials), "--db", str(db), "--no-plot", "--no-progress"],
        env=env, text=True, **{"stdout": subprocess.PIPE, "stderr": subprocess.PIPE, **popen})


def _log_with_bad_scenario(tmp) -> Path:
    """A trial log of one babble trial whose scenario column is then not UTF-8."""
    db = tmp / "bad_scenario.sqlite"
    if not db.exists():
        _babble(db, 1).communicate(timeout=300)
        conn = sqlite3.connect(db)
        conn.execute("UPDATE trials SET scenario = CAST(? AS TEXT)",
                     (b"\xff\xfe hand:\n  kind: barrett\n" * 20,))
        conn.commit()
        conn.close()
    return db


def _no_cache_locator():
    """numba finds no writable cache place (as a user who can write neither the
    package's __pycache__ nor a home cache): the import must still work."""
    code = ("import numba.core.caching as c\n"
            "c.CacheImpl._locator_classes = []\n"
            "import numpy as np\n"
            "from handle_drake.geometry.quality import grasp_quality, ContactParams\n"
            "P = np.array([[1, 1, 1], [1, -1, -1], [-1, 1, -1], [-1, -1, 1]]) / 3**0.5 * 0.05\n"
            "print(grasp_quality(P, -P / 0.05, ContactParams(characteristic_length=0.05))"
            ".force_closure)\n")
    env = dict(os.environ, PYTHONPATH=os.pathsep.join(p for p in sys.path if p))
    done = subprocess.run([sys.executable, "-W", "always", "-c", code], capture_output=True,
                          text=True, env=env, timeout=110)
    if "Traceback" in done.stderr:
        return "traceback", done.stderr.strip().splitlines()[-1][:200]
    ok = done.returncode == 0 and done.stdout.strip() == "True" and "cannot cache" in done.stderr
    return ("clean" if ok else "wrong",
            f"exit {done.returncode}, {done.stdout.strip()}, {done.stderr.strip()[:150]}")


def _log_rows(db):
    conn = sqlite3.connect(db)
    try:
        return conn.execute("SELECT trial_index, status FROM trials").fetchall()
    finally:
        conn.close()


def _probe_two_runs(tmp):
    """The same babble command twice at once on one log (the first stopped with SIGSTOP
    after its first trial while the second runs): the second must be refused naming the
    other process, the first then end with every trial done once."""
    db = tmp / "two.sqlite"
    first = _babble(db, 12)
    deadline = time.monotonic() + 120
    while time.monotonic() < deadline and not (db.exists() and _rows_or_none(db)):
        time.sleep(0.2)
    first.send_signal(signal.SIGSTOP)  # held mid-run (a loaded machine cannot race it)
    first_running = first.poll() is None
    second = _babble(db, 12)
    try:
        _, err2 = second.communicate(timeout=600)
    finally:
        first.send_signal(signal.SIGCONT)
    first.communicate(timeout=900)
    rows = _log_rows(db)
    ok = (second.returncode == 2 and "another process" in err2 and first.returncode == 0
          and first_running and sorted(i for i, s in rows if s == "done") == list(range(12)))
    record("process checks", "clean" if ok else "wrong",
           f"two runs on one log: second exit {second.returncode} "
           f"({err2.strip().splitlines()[-1][:120] if err2.strip() else ''}) while the first "
           f"ran: {first_running}; first exit "
           f"{first.returncode}, trials done {sorted(i for i, s in rows if s == 'done')}")


def _rows_or_none(db):
    try:
        return _log_rows(db)
    except sqlite3.Error:
        return None


def _probe_kill_and_resume(tmp, how):
    """babble killed (``kill -9``, or SIGINT) after its second trial, then run again: every
    trial done exactly once, none lost, and (SIGINT) exit 130 within 10 s."""
    db = tmp / f"resume_{how.replace(' ', '').replace('-', '')}.sqlite"
    run = _babble(db, 6)
    deadline = time.monotonic() + 300
    while time.monotonic() < deadline:
        rows = _rows_or_none(db) or []
        if sum(s == "done" for _, s in rows) >= 2:
            break
        time.sleep(0.1)
    start = time.monotonic()
    run.send_signal(signal.SIGKILL if how == "kill -9" else signal.SIGINT)
    try:
        run.communicate(timeout=30)
        took = time.monotonic() - start
    except subprocess.TimeoutExpired:
        run.kill()
        run.communicate()
        took = None
    before = sorted(i for i, s in _log_rows(db) if s == "done")
    again = _babble(db, 6)
    again.communicate(timeout=600)
    rows = _log_rows(db)
    indices = [i for i, _ in rows]
    ok = (again.returncode == 0 and sorted(indices) == list(range(6))
          and all(s == "done" for _, s in rows)
          and (how == "kill -9" or (run.returncode == 130 and took is not None and took < 10)))
    record("process checks", "clean" if ok else "wrong",
           f"{how} after {len(before)} trials done (exit {run.returncode}"
           f"{'' if took is None else f' in {took:.1f} s'}), resumed: exit {again.returncode}, "
           f"trials {sorted(indices)} ({len(indices) - len(set(indices))} duplicated, "
           f"{sum(s != 'done' for _, s in rows)} not done)")


def _children(pid):
    out = []
    for entry in os.listdir("/proc"):
        if entry.isdigit():
            try:
                fields = Path(f"/proc/{entry}/stat").read_text().rsplit(")", 1)[1].split()
            except OSError:
                continue
            if int(fields[1]) == pid and fields[0] != "Z":
                out.append(int(entry))
    return out


def _alive(pid):
    try:
        return Path(f"/proc/{pid}/stat").read_text().rsplit(")", 1)[1].split()[0] != "Z"
    except OSError:
        return False


def _probe_kill_9(tmp):
    """``babble --workers 2`` killed with SIGKILL while its pool runs trials: do its
    children outlive it by 5 s?"""
    env = dict(os.environ, PYTHONPATH=os.pathsep.join(p for p in sys.path if p))
    parent = subprocess.Popen(
        [sys.executable, "-m", "handle_drake.cli", "babble", "--workers", "2", "--strategy",
         "random", "--trials", "6", "--db", str(tmp / "k9.sqlite"), "--no-plot",
         "--no-progress"], stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL, env=env)
    deadline = time.monotonic() + 120
    while len(_children(parent.pid)) < 2 and time.monotonic() < deadline:
        time.sleep(0.5)
    time.sleep(3)
    children = _children(parent.pid)
    parent.kill()
    parent.wait()
    time.sleep(5)
    left = [c for c in children if _alive(c)]
    for c in left:
        os.kill(c, signal.SIGKILL)
    record("kill -9", "clean" if children and not left else "wrong",
           f"babble --workers 2: {len(children)} children, {len(left)} alive 5 s after kill -9")


def _probe_ctrl_c(tmp):
    """SIGINT to a process decomposing a 150k-triangle torus with CoACD: how long
    until it and its children are gone?"""
    import trimesh

    torus = tmp / "torus.obj"
    trimesh.creation.torus(0.05, 0.015, major_sections=500, minor_sections=150).export(torus)
    code = ("import numpy as np, trimesh, sys\n"
            "from handle_drake.geometry.objects.mesh import convex_decomposition\n"
            f"m = trimesh.load({str(torus)!r}, force='mesh')\n"
            "print('start', flush=True)\n"
            "try:\n    convex_decomposition(m.vertices, m.faces, directory=sys.argv[1])\n"
            "except KeyboardInterrupt:\n    sys.exit(130)\n")
    env = dict(os.environ, PYTHONPATH=os.pathsep.join(p for p in sys.path if p))
    child = subprocess.Popen([sys.executable, "-c", code, str(tmp / "cache")],
                             stdout=subprocess.PIPE, stderr=subprocess.DEVNULL, env=env,
                             text=True)
    child.stdout.readline()
    time.sleep(8)  # the decomposition child is spawned and busy
    grandchildren = _children(child.pid)
    child.send_signal(signal.SIGINT)
    start = time.monotonic()
    try:
        child.wait(15)
        took = time.monotonic() - start
    except subprocess.TimeoutExpired:
        took = None
        child.kill()
        child.wait()
    time.sleep(1)
    left = [c for c in grandchildren if _alive(c)]
    for c in left:
        os.kill(c, signal.SIGKILL)
    ok = took is not None and took < 3 and not left
    record("meshes", "clean" if ok else ("hang" if took is None else "wrong"),
           f"Ctrl-C during CoACD ({len(trimesh.load(torus).faces)} triangles): exit after "
           f"{'>15' if took is None else f'{took:.1f}'} s, {len(left)} children left")


def main():
    # `--no-page` / `--results-page PATH` as the other benchmarks (no argparse here: the
    # positional part name picks one part).
    page = argparse.ArgumentParser(add_help=False)
    add_page_arguments(page, "hostile_probe")
    page_args, sys.argv[1:] = page.parse_known_args(sys.argv[1:])
    results_run = ResultsRun("Hostile input probe: inputs tried, refused cleanly, failures",
                             page_args)
    only = {"can": probe_can, "second": probe_second_wave, "third": probe_third_wave,
            "fourth": probe_fourth_wave}
    if sys.argv[1:2] and sys.argv[1] in only:  # one part only ('can' needs the least time)
        with tempfile.TemporaryDirectory() as tmp:
            only[sys.argv[1]](Path(tmp))
        print(json.dumps({k: {n: v for n, v in r.items() if n != "failures"} | {
            "failures": r["failures"]} for k, r in RESULTS.items()}, indent=1))
        if sys.argv[1] in ("third", "fourth"):  # `third|fourth before|after`: an issue's table
            label = sys.argv[2] if len(sys.argv) > 2 else "run"
            OUT.mkdir(parents=True, exist_ok=True)
            results_run.finish(_table(), RESULTS,
                               OUT / f"hostile_probe_{sys.argv[1]}_{label}.json")
            print("| surface | tried | clean | traceback | hang | wrong (silent accept) |\n"
                  "|---|---|---|---|---|---|")
            for part, r in RESULTS.items():
                print(f"| {part} | {r['tried']} | {r['clean']} | {r['traceback']} | "
                      f"{r['hang']} | {r['wrong']} |")
        return
    with tempfile.TemporaryDirectory() as tmp:
        tmp = Path(tmp)
        for name, function in (("scenario", probe_scenarios), ("cli", lambda: probe_cli(tmp)),
                               ("quality", probe_quality),
                               ("log", lambda: probe_trial_log(tmp)),
                               ("can", lambda: probe_can(tmp)),
                               ("second wave", lambda: probe_second_wave(tmp))):
            start = time.monotonic()
            function()
            print(f"{name}: {time.monotonic() - start:.1f} s", file=sys.stderr)
    print("| part | tried | clean | traceback | hang | wrong |\n|---|---|---|---|---|---|")
    for part, r in RESULTS.items():
        print(f"| {part} | {r['tried']} | {r['clean']} | {r['traceback']} | {r['hang']} | "
              f"{r['wrong']} |")
    for part, r in RESULTS.items():
        for failure in r["failures"][:20]:
            print(f"  {part}: {failure}")
    OUT.mkdir(parents=True, exist_ok=True)
    results_run.finish(_table(), RESULTS, OUT / "hostile_probe.json")


def _table() -> list[dict]:
    return [{"part": part, **{k: r[k] for k in ("tried", "clean", "traceback", "hang", "wrong")}}
            for part, r in RESULTS.items()]


if __name__ == "__main__":
    main()
