"""The README walked as a newcomer walks it: every command line of its code blocks, run in
order from an empty folder (no checkout around it: the shipped diagrams by their README paths,
the console script as installed), with reduced budgets where a line asks for minutes.

``WALK`` pairs each README line with what runs here: the line itself, or the same command with
smaller budgets (and the exit code it is documented to give when it cannot work on this
machine: a MIDI device, a Dask head node). A README line missing from ``WALK`` (or a ``WALK``
line no longer in the README) fails the fast test, so the walk follows the README.

Run alone to print the walk's table (command, exit code, seconds):
``python tests/test_readme_walk.py``.
"""

from __future__ import annotations

import os
import re
import shlex
import shutil
import signal
import sqlite3
import subprocess
import sys
import time
from dataclasses import dataclass
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
README = ROOT / "README.md"
ENV = {**os.environ, "OPENBLAS_NUM_THREADS": "1", "MPLBACKEND": "Agg",
       "HANDLE_DRAKE_REDUCED": "1"}
#: The set-up lines: what the suite itself is (creating this venv, installing, running it).
SETUP = ("python3 -m venv", "source ", "pip install", "python -m pytest",
         "OPENBLAS_NUM_THREADS=1 python -m pytest", "export ")
NO_PLACE = "127.0.0.1:9"  # nothing listens on the discard port: a refused connection


@dataclass(frozen=True)
class Step:
    readme: str  # the line as the README writes it (without its comment)
    run: str | None = None  # what runs here (None: the line itself)
    code: int = 0  # the documented exit code here
    why: str = ""  # why it differs from the README line


WALK: tuple[Step, ...] = (
    Step("handle-drake demo"),
    Step("handle-drake simulate diagrams/shadow_sphere_grasp.yaml --meshcat",
         "handle-drake simulate diagrams/shadow_sphere_grasp.yaml --meshcat --duration 0.2",
         why="0.2 s of the scenario"),
    Step("handle-drake simulate diagrams/barrett_cylinder_grasp.yaml --html out/barrett.html"),
    Step("handle-drake synergies --plot out/synergies.png"),
    Step("handle-drake grasp --class tripod --object sphere --size 0.04 --html out/tripod.html"),
    Step("handle-drake babble --hand barrett --object mug --dims 2 --strategy bo --trials 100 "
         "--seed 0 --db out/babble.sqlite",
         "handle-drake babble --hand barrett --object mug --dims 2 --strategy bo --trials 3 "
         "--seed 0 --db out/babble.sqlite --no-progress", why="3 trials"),
    Step("handle-drake report --out out/report", "handle-drake report --out out/report --reduced "
         "--no-progress", why="--reduced: tiny grids, few trials"),
    Step("handle-drake simulate trial.yaml", why="trial.yaml: a trial's scenario saved from "
                                                 "out/babble.sqlite first, as the README says"),
    Step("handle-drake babble --strategy random --trials 400 --executor dask --workers 2",
         "handle-drake babble --strategy random --trials 2 --executor dask --workers 2 "
         "--no-progress --db out/dask.sqlite", why="2 trials"),
    Step("handle-drake babble --object sphere --placement-error 0.002 --placement-samples 5",
         "handle-drake babble --object sphere --placement-error 0.002 --placement-samples 2 "
         "--trials 2 --no-progress --db out/robust.sqlite", why="2 trials of 2 placements"),
    Step("python benchmarks/bench_babbling.py --surrogate --grid 13 --trials 60 "
         "--placement-error 0.002",
         "python benchmarks/bench_babbling.py --surrogate --grid 3 --trials 10 "
         "--placement-error 0.002 --placement-samples 2 --seeds 1 --skopt-seeds 1 "
         "--objects sphere --validate-points 0 --out out/bench_babbling --no-page",
         why="one object, a 3x3 grid, 10 trials, one seed; no results page"),
    Step("handle-drake inhand --task cylinder_rotation --optimizer ipso --trials 1000 --seed 0 "
         "--db out/inhand/inhand.sqlite",
         "handle-drake inhand --task cylinder_rotation --optimizer ipso --trials 2 --seed 0 "
         "--db out/inhand/inhand.sqlite --no-progress", why="2 trials"),
    Step("handle-drake inhand --task star_rotation --optimizer cmaes --trials 100 --workers 2",
         "handle-drake inhand --task star_rotation --optimizer cmaes --trials 2 --workers 2 "
         "--particles 2 --no-progress", why="2 trials"),
    Step("handle-drake inhand --optimizer ipso --trials 1000 --executor dask --workers 2",
         "handle-drake inhand --optimizer ipso --trials 2 --particles 2 --executor dask "
         "--workers 2 --no-progress --db out/inhand/dask.sqlite", why="2 trials"),
    Step("handle-drake inhand --accelerometer joywarrior24f14 --trials 100",
         "handle-drake inhand --accelerometer joywarrior24f14 --trials 2 --no-progress",
         why="2 trials, in the log of the first inhand line"),
    Step("handle-drake inhand --task screw_cap --optimizer ipso --trials 200",
         "handle-drake inhand --task screw_cap --optimizer ipso --trials 2 --no-progress",
         why="2 trials"),
    Step("handle-drake inhand --task fingertip_cylinder --trials 150",
         "handle-drake inhand --task fingertip_cylinder --trials 2 --no-progress",
         why="2 trials"),
    Step("handle-drake inhand --task jog_wheel --optimizer ipso --trials 60",
         "handle-drake inhand --task jog_wheel --optimizer ipso --trials 2 --no-progress",
         why="2 trials"),
    Step("handle-drake simulate diagrams/inhand_jog_wheel.yaml"),
    Step("handle-drake simulate diagrams/screw_cap_station.yaml"),
    Step("handle-drake simulate diagrams/barrett_mesh_bracket_grasp.yaml --html out/bracket.html"),
    Step("handle-drake grasp --class lateral --mesh diagrams/meshes/part.stl --mesh-scale 0.001"),
    Step("handle-drake babble --mesh diagrams/meshes/part.stl --mesh-scale 0.001 --trials 40",
         "handle-drake babble --mesh diagrams/meshes/part.stl --mesh-scale 0.001 --trials 2 "
         "--no-progress --db out/mesh.sqlite", why="2 trials"),
    Step("handle-drake report --out out/report --mesh diagrams/meshes/part.stl --mesh-scale 0.001",
         "handle-drake report --out out/report --mesh diagrams/meshes/part.stl --mesh-scale "
         "0.001 --reduced --no-progress", why="--reduced"),
    Step("handle-drake can-sim --bus udp_multicast &", why="in the background until the walk ends"),
    Step("handle-drake can-server --listen 127.0.0.1:47800 --bus udp_multicast &",
         why="in the background until the walk ends"),
    Step("handle-drake simulate diagrams/shadow_can_hand.yaml --hardware",
         "handle-drake simulate diagrams/shadow_can_hand.yaml --hardware --duration 0.5",
         why="0.5 s in real time"),
    Step("handle-drake instruments --plot out/figure8.png --json out/figure8.json"),
    Step("handle-drake simulate diagrams/instrumented_joywarrior_tripod.yaml "
         "--html out/joywarrior.html"),
    Step("handle-drake grasp --class parallel_extension --object wiimote"),
    Step("handle-drake perceive diagrams/tabletop_perception.yaml --json"),
    Step("handle-drake perceive diagrams/tabletop_perception.yaml --save-frames out/frames"),
    Step("handle-drake perceive --frame out/frames/kinect.json"),
    Step("handle-drake grasp --class tripod --object cuboid --size 0.075 --xy 0.05 -0.03 "
         "--yaw 30 --perceived"),
    Step("python benchmarks/bench_perception_objects.py --poses 8",
         "python benchmarks/bench_perception_objects.py --poses 1 --objects sphere --out "
         "out/bench_perception_objects.json --no-page", why="1 pose of 1 object; no page"),
    Step("handle-drake simulate diagrams/hamburg_setup.yaml --html out/hamburg.html"),
    Step("handle-drake pick diagrams/hamburg_setup.yaml --kind sphere --html out/pick.html"),
    Step("handle-drake pick diagrams/hamburg_setup.yaml --scene-seed 3 --true-poses"),
    Step("handle-drake pick diagrams/hamburg_setup.yaml --build-grasp-db",
         "handle-drake pick diagrams/hamburg_setup.yaml --build-grasp-db --grasp-db "
         "out/grasp_db.json", why="into out/ (the README's line rewrites the shipped file)"),
    Step("handle-drake pick diagrams/paris_setup.yaml --scene-seed 1"),
    Step("handle-drake pick diagrams/sorter_setup.yaml --kind star_prism --true-poses"),
    Step("python benchmarks/bench_pick.py --seeds 0-19",
         "python benchmarks/bench_pick.py --seeds 0 --plan-only --out out/bench_pick --no-page",
         why="1 seed, planned only; no page"),
    Step("python benchmarks/bench_arm_reachability.py --places 2",
         "python benchmarks/bench_arm_reachability.py --places 1 --out out/bench_arm --no-page",
         why="1 place; no page"),
    Step("handle-drake grasp --class tip_pinch --object sphere --size 0.0225 --pose-error 0.007 "
         "0.008 --open-loop", code=1,
         why="the README's point: open loop drops the ball (DROPPED, exit 1)"),
    Step("handle-drake grasp --class tip_pinch --object sphere --size 0.0225 --pose-error 0.007 "
         "0.008 --recentre"),
    Step("python benchmarks/bench_grasp_classes.py --sizes 3 --offset 10",
         "python benchmarks/bench_grasp_classes.py --sizes 1 --offset 10 --classes tripod "
         "--no-page", why="1 size of 1 class; no page"),
    Step("handle-drake midi jog --html out/jog.html"),
    Step("handle-drake midi fader"),
    Step("handle-drake simulate diagrams/midi_jog_pinch.yaml"),
    Step("handle-drake midi control --meshcat", "handle-drake midi control --meshcat "
         "--duration 0.5", why="0.5 s"),
    Step("handle-drake midi control --hardware --scenario diagrams/shadow_can_hand.yaml",
         "handle-drake midi control --hardware --scenario diagrams/shadow_can_hand.yaml "
         "--duration 0.5", code=2, why="no MIDI device here (exit 2, one line)"),
    Step("handle-drake midi ports", code=2, why="no ALSA sequencer here (exit 2, one line)"),
    Step("handle-drake midi monitor", code=2, why="no MIDI device here (exit 2, one line)"),
    Step("handle-drake midi write-scenarios diagrams"),
    Step("handle-drake --help"),
    Step("dask scheduler --port 8786", None, why="a daemon on the head node: not run"),
    Step("dask worker tcp://HEAD:8786 --nworkers auto --nthreads 1", None,
         why="a daemon on each compute machine: not run"),
    Step("handle-drake babble --object mug --strategy random --trials 2000 "
         "--executor dask://HEAD:8786",
         f"handle-drake babble --object mug --strategy random --trials 2 --executor "
         f"dask://{NO_PLACE} --connect-timeout 1", code=2,
         why="no head node here: the documented one-line error"),
    Step("handle-drake report --out out/report --executor dask://HEAD:8786",
         f"handle-drake report --out out/report --executor dask://{NO_PLACE} "
         "--connect-timeout 1", code=2, why="no head node here"),
    Step("handle-drake inhand --optimizer ipso --trials 1000 --executor dask://HEAD:8786",
         f"handle-drake inhand --optimizer ipso --trials 2 --executor dask://{NO_PLACE} "
         "--connect-timeout 1", code=2, why="no head node here"),
)
NOT_RUN = {"dask scheduler --port 8786",
           "dask worker tcp://HEAD:8786 --nworkers auto --nthreads 1"}


def readme_lines(text: str | None = None) -> list[str]:
    """Each command of the README's ``bash`` code blocks, in order: comments dropped,
    ``a && b`` as two commands, the set-up lines (the suite itself) left out."""
    text = README.read_text() if text is None else text
    lines = []
    for block in re.findall(r"```bash\n(.*?)```", text, re.S):
        for line in block.splitlines():
            line = re.split(r"\s+#", line, maxsplit=1)[0].strip()
            if not line or line.startswith("#"):
                continue
            for part in (p.strip() for p in line.split("&&")):
                if part and not part.startswith(SETUP):
                    lines.append(re.sub(r"\s+", " ", part))
    return lines


def test_the_walk_covers_every_readme_command_and_nothing_else():
    lines = readme_lines()
    walked = [step.readme for step in WALK]
    assert "handle-drake demo" in lines and len(lines) > 40  # the extraction sees them
    missing = [line for line in dict.fromkeys(lines) if line not in walked]
    stale = [line for line in walked if line not in lines]
    assert not missing, f"README commands with no step in WALK: {missing}"
    assert not stale, f"WALK steps no longer in the README: {stale}"
    for step in WALK:
        if step.run is not None:  # a reduced line is the README's command with other budgets
            assert shlex.split(step.run)[:2] == shlex.split(step.readme)[:2], step.readme


def _argv(line: str) -> list[str]:
    words = shlex.split(line.rstrip("& "))
    if words[0] == "handle-drake":
        script = Path(sys.executable).parent / "handle-drake"
        return [str(script) if script.exists() else shutil.which("handle-drake"), *words[1:]]
    if words[0] == "python":
        return [sys.executable, str(ROOT / words[1]), *words[2:]]
    return words


def _save_a_trial(folder: Path) -> None:
    """The README: save a logged trial's scenario from the log's `scenario` column."""
    with sqlite3.connect(folder / "out" / "babble.sqlite") as db:
        (scenario,) = db.execute("SELECT scenario FROM trials WHERE status = 'done' "
                                 "ORDER BY trial_index LIMIT 1").fetchone()
    (folder / "trial.yaml").write_text(scenario)


def walk(folder: Path, steps=WALK, echo=None) -> list[tuple[Step, int | None, float, str]]:
    """Runs ``steps`` in order in ``folder``; (step, exit code, seconds, last output line)."""
    results, background = [], []
    try:
        for step in steps:
            if step.readme in NOT_RUN:
                results.append((step, None, 0.0, step.why))
                continue
            line = step.run or step.readme
            if step.readme == "handle-drake simulate trial.yaml":
                _save_a_trial(folder)
            start = time.monotonic()
            if line.endswith("&"):
                process = subprocess.Popen(_argv(line), cwd=folder, env=ENV, text=True,
                                           stdout=subprocess.PIPE, stderr=subprocess.STDOUT,
                                           start_new_session=True)
                background.append(process)
                ready = process.stdout.readline().strip()  # each prints a line when ready
                code = None if process.poll() is None else process.returncode
                results.append((step, code, time.monotonic() - start, ready))
            else:
                done = subprocess.run(_argv(line), cwd=folder, env=ENV, text=True,
                                      capture_output=True, timeout=900)
                output = ((done.stderr if done.returncode else done.stdout).strip()
                          or (done.stdout + done.stderr).strip()).splitlines()
                results.append((step, done.returncode, time.monotonic() - start,
                                output[-1] if output else ""))
            if echo:
                echo(results[-1])
    finally:
        for process in background:
            os.killpg(process.pid, signal.SIGTERM)
            process.wait(timeout=30)
    return results


def failures(results) -> list[str]:
    bad = []
    for step, code, _, last in results:
        if step.readme in NOT_RUN:
            continue
        expected = None if step.readme.endswith("&") else step.code
        if code != expected:
            bad.append(f"{step.run or step.readme}: exit {code}, expected {expected}: {last}")
    return bad


def test_every_readme_command_line_is_accepted_by_its_parser():
    """The suite's reduced walk: every README line (as written, and its reduced form) is
    accepted by the handle-drake parser, and every benchmark line names a shipped script.
    The full walk below runs them all (about 37 min here, more than CI's budget)."""
    from handle_drake.cli import build_parser

    parser = build_parser()
    for step in WALK:
        if step.readme in NOT_RUN:
            continue
        for line in dict.fromkeys((step.readme, step.run or step.readme)):
            words = shlex.split(line.rstrip("& "))
            if words[0] == "handle-drake":
                try:
                    parser.parse_args(words[1:])
                except SystemExit as error:
                    if error.code == 0:  # --help
                        continue
                    pytest.fail(f"{line}: refused by the parser (exit {error.code})")
            elif words[0] == "python":
                assert (ROOT / words[1]).is_file(), f"{line}: no {words[1]}"


FULL_WALK = os.environ.get("HANDLE_DRAKE_README_WALK") == "1"


@pytest.mark.slow
@pytest.mark.skipif(not FULL_WALK, reason="the full README walk (~37 min here, over CI's "
                    "budget) runs with HANDLE_DRAKE_README_WALK=1 or `python "
                    "tests/test_readme_walk.py`; the suite checks every line's parse")
def test_every_readme_command_runs_from_an_empty_folder(tmp_path):
    results = walk(tmp_path)
    assert not failures(results), "\n".join(failures(results))
    # what the walk made is where the README says
    for made in ("out/demo.html", "out/barrett.html", "out/synergies.png",
                 "out/frames/kinect.json", "diagrams/midi_jog_pinch.yaml"):
        assert (tmp_path / made).is_file(), made


if __name__ == "__main__":
    import tempfile

    def show(result):
        step, code, seconds, last = result
        print(f"| `{step.run or step.readme}` | {code} | {seconds:.1f} | {last[:70]} |",
              flush=True)

    print("| command | exit | s | last line |\n|---|---|---|---|")
    with tempfile.TemporaryDirectory() as folder:
        results = walk(Path(folder), echo=show)
    print("\n".join(failures(results)) or "all as documented")
