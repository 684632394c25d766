"""Property-based fuzzing (hypothesis) of every public input surface.

Properties, for any input the strategies can build:

- the scenario loader returns a validated ``Scenario`` or raises a
  ``ValueError`` (``ScenarioError``), ``TypeError`` or ``FileNotFoundError``;
- the command line (in process, through ``run_command`` with argv) exits 0 or
  2 (argparse's own usage errors exit 2 too) and never prints a traceback;
  the long-running parts (simulation, optimisation runs, serving) are replaced
  by stubs *after* argument parsing, output checks and scenario validation;
- the grasp quality API returns a finite value or raises ``ValueError`` /
  ``TypeError``;
- the CAN TCP protocol's stream reader and payload decoders, the frame
  decoders of both layouts and the received-frame check return a result or
  raise their documented ``ValueError`` subclasses.

Any other exception type fails the property. Example counts are small and
deadlines off, so the file costs seconds in CI (``--durations`` shows it); a
longer local run: ``HYPOTHESIS_PROFILE=long pytest tests/fuzz``.
"""

import io
import os
import threading
from contextlib import redirect_stderr, redirect_stdout
from types import SimpleNamespace

import numpy as np
import pytest
import yaml
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

CLEAN = (ValueError, TypeError, FileNotFoundError)

# -- building blocks -----------------------------------------------------------------
numbers = st.one_of(
    st.floats(allow_nan=True, allow_infinity=True),
    st.sampled_from([0, -1, 1e-300, 1e300, 5e-324, 1e-9, 10, 0.001, 0.06, 2.0, -0.0]),
    st.integers(min_value=-(2**70), max_value=2**70),
)
scalars = st.one_of(numbers, st.text(max_size=20), st.booleans(), st.none())
values = st.recursive(scalars, lambda inner: st.one_of(
    st.lists(inner, max_size=4), st.dictionaries(st.text(max_size=8), inner, max_size=4)),
    max_leaves=8)
FIELDS = {
    "hand": ["kind", "coupling_ratio", "mount", "initial_position"],
    "object": ["kind", "size", "dimensions", "mass", "mu", "X_WO", "on_table", "fixed"],
    "table": ["top_height", "size_x", "size_y"],
    "driver": ["max_joint_velocity", "control_period", "host", "port", "period"],
    "plant_config": ["time_step", "contact_model", "discrete_contact_approximation",
                     "penetration_allowance", "stiction_tolerance", "sap_near_rigid_threshold",
                     "contact_surface_representation", "use_sampled_output_ports",
                     "adjacent_bodies_collision_filters"],
    # The deprecated top-level plant keys are still translated: fuzz them too.
    "": ["contact_model", "time_step", "contact_approximation", "plant_config",
         "simulation_duration", "random_seed", "script", "visualization"],
}
TAGS = ["", "!SimHandDriver ", "!CanHandDriver ", "!FloatingWrist ", "!FixedMount ", "!Foo ",
        "!Rpy ", "!AngleAxis ", "!Uniform "]
poses = st.fixed_dictionaries({}, optional={
    "translation": st.one_of(st.lists(numbers, min_size=0, max_size=4), values),
    "rotation": st.one_of(values, st.fixed_dictionaries({"deg": st.lists(numbers, max_size=4)}),
                          st.fixed_dictionaries({"angle_deg": numbers,
                                                 "axis": st.lists(numbers, max_size=4)})),
    "base_frame": st.one_of(st.text(max_size=10), st.just("world")),
})


@st.composite
def scenario_texts(draw):
    """YAML override text: real fields with hostile values, tags in odd places,
    duplicate keys, unknown fields, and sometimes arbitrary text."""
    if draw(st.integers(0, 9)) == 0:
        return draw(st.text(max_size=200))
    lines = []
    for _ in range(draw(st.integers(1, 4))):
        section = draw(st.sampled_from(sorted(FIELDS)))
        field = draw(st.sampled_from(FIELDS[section] + ["bogus"]))
        if field in ("X_WO",) or (field == "mount" and draw(st.booleans())):
            value = {"X_WB": draw(poses)} if field == "mount" else draw(poses)
        else:
            value = draw(values)
        tag = draw(st.sampled_from(TAGS))
        text = yaml.safe_dump(value, default_flow_style=True, width=10_000).strip()
        text = text.removesuffix("...").strip()
        if section:
            lines.append(f"{section}: {tag}{{{field}: {text}}}")
        else:
            lines.append(f"{field}: {tag}{text}")
    return "\n".join(lines) + "\n"


# -- scenario loader -------------------------------------------------------------------
@pytest.mark.filterwarnings(  # the deprecated plant keys it draws on purpose
    "ignore::handle_drake.base.checks.ScenarioDeprecationWarning")
@given(text=scenario_texts())
def test_scenario_loader_accepts_or_refuses_cleanly(text):
    from handle_drake.scenario import LoadScenario, Scenario, validate_scenario

    try:
        scenario = LoadScenario(data=text)
    except CLEAN:
        return
    assert isinstance(scenario, Scenario)
    validate_scenario(scenario)  # what was accepted stays valid


# -- command line ----------------------------------------------------------------------
HEAVY = ("demo", "grasp", "synergies", "babble", "report")


@pytest.fixture(scope="module")
def cli(tmp_path_factory):
    """``run(argv) -> (code, stderr)`` with the long-running work stubbed."""
    import handle_drake.devices.can_hand.cli as can_cli
    import handle_drake.trial.simulate as run_module
    from handle_drake import cli as top

    tmp = tmp_path_factory.mktemp("fuzzcli")
    (tmp / "ok.yaml").write_text("simulation_duration: 0.01\n")
    (tmp / "dir").mkdir()
    os.mkfifo(tmp / "fifo")

    class FakeRunner:  # after LoadScenario and every check: the simulation itself
        def __init__(self, scenario, meshcat=None, hardware=False):
            self.scenario = scenario

        def run(self, duration=None, html=None):
            return SimpleNamespace(sim_time=0.0, wall_time=1.0, realtime_factor=0.0,
                                   object_position=None, score=None)

        def grasp_quality(self):
            return 0.0, False, {}

    def stopped_event():
        event = threading.Event()
        event.set()
        return event

    patches = [(run_module, "ScenarioRunner", FakeRunner), (can_cli, "_stop_event", stopped_event),
               (can_cli, "_freeze_heap", lambda: None)]
    saved = [(m, n, getattr(m, n)) for m, n, _ in patches]
    for module, name, value in patches:
        setattr(module, name, value)
    parser = top.build_parser()
    for action in parser._subparsers._group_actions:
        for name, sub in action.choices.items():
            if name in HEAVY:
                sub.set_defaults(func=lambda args: 0)

    def run(argv):
        out, err = io.StringIO(), io.StringIO()
        with redirect_stdout(out), redirect_stderr(err):
            try:
                code = top.run_command(parser, argv)
            except SystemExit as exit_:  # argparse: usage errors 2, --help 0
                code = exit_.code
        return code, err.getvalue()

    yield SimpleNamespace(run=run, tmp=tmp)
    for module, name, value in saved:
        setattr(module, name, value)


def _tokens(tmp):
    paths = [str(tmp / "ok.yaml"), str(tmp / "dir"), str(tmp / "fifo"), str(tmp / "missing.yaml"),
             str(tmp / ("x" * 300)), str(tmp / "ok.yaml" / "below"), "/", ""]
    return st.one_of(st.sampled_from(paths), st.text(max_size=12),
                     numbers.map(str), st.sampled_from(["127.0.0.1:0", "nope", "1.2.3.4:99999",
                                                        "[::1]:0", "virtual", "socketcan"]))


OPTIONS = {
    "simulate": ["--override", "--duration", "--html", "--hardware", "--quality"],
    "can-server": ["--listen", "--hand", "--max-rate", "--max-step", "--watchdog",
                   "--max-clients", "--hello-timeout", "--max-client-backlog",
                   "--frame-format", "--rt-priority", "--coupling-ratio", "--bus-port",
                   "--multicast-interface"],
    "can-sim": ["--hand", "--rate", "--natural-frequency", "--max-velocity", "--noise",
                "--object-closure", "--seed", "--frame-format", "--coupling-ratio"],
    "demo": ["--html", "--no-html"],
    "grasp": ["--class", "--object", "--size", "--html", "--save-scenario"],
    "synergies": ["--k-max", "--plot"],
    "babble": ["--trials", "--seed", "--db", "--noise", "--dims", "--workers", "--plot"],
    "report": ["--out", "--seeds", "--trials", "--grid"],
}


@st.composite
def argvs(draw, tmp):
    command = draw(st.sampled_from(sorted(OPTIONS)))
    argv = [command]
    tokens = _tokens(tmp)
    if command in ("simulate", "synergies"):
        argv.append(draw(tokens))
    for _ in range(draw(st.integers(0, 4))):
        argv.append(draw(st.sampled_from(OPTIONS[command])))
        if draw(st.integers(0, 4)):
            argv.append(draw(tokens))
    if command in ("can-server", "can-sim"):
        argv += ["--bus", "virtual", "--channel", f"fuzz-{os.getpid()}"]
        if command == "can-server":
            argv += ["--listen", "127.0.0.1:0"]  # never a fixed port on a shared machine
    if command == "simulate" and "--hardware" in argv:
        argv.remove("--hardware")  # would wait for a CAN server
    return argv


@given(data=st.data())
def test_command_line_exits_0_or_2_without_traceback(cli, data):
    argv = data.draw(argvs(cli.tmp))
    code, err = cli.run(argv)
    assert code in (0, 2), (argv, code, err[-2000:])
    assert "Traceback" not in err, (argv, err[-2000:])


# -- grasp quality ---------------------------------------------------------------------
arrays = st.one_of(
    st.integers(0, 5).flatmap(lambda n: st.lists(st.lists(numbers, min_size=3, max_size=3),
                                                 min_size=n, max_size=n)),
    values,
    st.just(np.ones((3, 3)) * (1 + 1j)),
    st.just(np.full((2, 3), np.nan)),
)
params = st.fixed_dictionaries({}, optional={
    "mu": st.one_of(numbers, st.just(0.5 + 0j), st.text(max_size=3)),
    "gamma": numbers, "num_edges": st.one_of(st.integers(-3, 300), numbers),
    "characteristic_length": numbers,
    "model": st.sampled_from(["soft_finger", "point_friction", "frictionless", "glue"]),
})


@given(points=arrays, normals=arrays, options=params,
       method=st.sampled_from(["fast", "drake", "magic"]))
def test_quality_api_returns_a_finite_value_or_refuses_cleanly(points, normals, options, method):
    from handle_drake.geometry.quality import ContactParams, grasp_quality

    try:
        q = grasp_quality(points, normals, ContactParams(**options), method=method)
    except (ValueError, TypeError):
        return
    assert np.isfinite(q.value) and q.distance >= 0 and q.radius >= 0


@given(W=st.one_of(st.lists(st.lists(numbers, min_size=6, max_size=6), max_size=12), values),
       method=st.sampled_from(["fast", "drake"]))
def test_quality_from_wrenches_returns_a_finite_value_or_refuses_cleanly(W, method):
    from handle_drake.geometry.quality import quality_from_wrenches

    try:
        q = quality_from_wrenches(W, method=method)
    except (ValueError, TypeError):
        return
    assert np.isfinite(q.value)


# -- CAN protocol and frames -------------------------------------------------------------
@given(chunks=st.lists(st.binary(max_size=64), max_size=6))
def test_protocol_stream_reader_and_payload_decoders(chunks):
    from handle_drake.devices.can_hand import protocol as P

    reader = P.FrameReader()
    info = P.HandInfo("shadow", 24, 20, 5)
    for chunk in chunks:
        try:
            messages = reader.feed(chunk)
        except P.ProtocolError:
            return
        for _, payload in messages:
            for decode in (P.unpack_hello, lambda b: P.unpack_command(b, 20),
                           lambda b: P.unpack_state(b, info), P.unpack_stats):
                try:
                    decode(payload)
                except P.PayloadError:
                    pass
    for decode in (P.unpack_hello, lambda b: P.unpack_command(b, 20),
                   lambda b: P.unpack_state(b, info), P.unpack_stats):
        try:
            decode(b"".join(chunks))
        except P.PayloadError:
            pass


@pytest.fixture(scope="module")
def codecs():
    from handle_drake.devices.can_hand.layout import hand_layout
    from handle_drake.devices.can_hand.messages import make_codec

    return [make_codec(hand_layout(kind), fmt) for kind in ("shadow", "barrett")
            for fmt in ("classic", "fd")]


@given(frames=st.lists(st.tuples(st.one_of(st.integers(0, 0x7FF), st.integers(-5, 2**32)),
                                 st.binary(max_size=70), st.booleans()), max_size=12))
def test_frame_decoders_return_or_raise_can_frame_errors(codecs, frames):
    from handle_drake.devices.can_hand.messages import CanFrameError

    for codec in codecs:
        receivers = (codec.feedback_receiver(), codec.setpoint_receiver())
        for arbitration_id, data, is_fd in frames:
            for receiver in receivers:
                try:
                    receiver.feed(arbitration_id, data, is_fd)
                except CanFrameError:
                    pass


@given(fields=st.fixed_dictionaries({
    "arbitration_id": st.one_of(st.integers(-5, 2**40), numbers, st.text(max_size=4),
                                st.booleans(), st.none()),
    "data": st.one_of(st.binary(max_size=80), st.text(max_size=4), st.none(), numbers),
    "is_fd": st.one_of(st.booleans(), scalars), "is_extended_id": st.one_of(st.booleans(), scalars),
    "is_error_frame": st.one_of(st.booleans(), scalars),
    "is_remote_frame": st.one_of(st.booleans(), scalars)}))
def test_received_frame_check_takes_any_field_types(codecs, fields):
    from handle_drake.devices.can_hand.bus import check_frame
    from handle_drake.devices.can_hand.messages import CanFrameError

    try:
        arbitration_id, data, is_fd = check_frame(SimpleNamespace(**fields))
    except CanFrameError:
        return
    assert type(arbitration_id) is int and isinstance(data, bytes) and type(is_fd) is bool
    for codec in codecs:  # what passes the check is safe for every decoder
        for receiver in (codec.feedback_receiver(), codec.setpoint_receiver()):
            try:
                receiver.feed(arbitration_id, data, is_fd)
            except CanFrameError:
                pass
