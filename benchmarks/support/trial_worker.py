"""A trial timed in another process, for a benchmark's before/after in one run.

``python benchmarks/support/trial_worker.py KIND OPTIONS_JSON`` builds the in-hand trial
(``screw_cap``: ``ScrewCapTrial(ScrewCapTask(**options))``; ``inhand``:
``InHandTrial(InHandTask(**options))``; ``KIND:bare`` / ``inhand:replay``: that trial's
floor from ``floors.py``, so that each case of a speed table can run in a process of its
own) with whatever ``handle_drake`` the process imports first (``PYTHONPATH`` pointing at
a tree extracted from a git revision: the "before"),
settles it, prints ``ready`` and then, for each ``run`` line on stdin, evaluates the
hand-written stroke once and prints one JSON line: the trial's wall time and its outcome
(for the bit-identity check against this tree's). :class:`BaselineTrial` runs it from a
revision. ``trial_worker.py --count KIND OPTIONS_JSON N`` runs it once, then ``N`` times
inside ``itertools.starmap`` (the C function ``instructions.py`` counts in).
"""

from __future__ import annotations

import json
import os
import subprocess
import sys
import tarfile
import tempfile
from pathlib import Path

ROOT = Path(__file__).resolve().parents[2]


def stroke(gist):
    """The hand-written stroke (J3 1.0, J2 0.9 on the fingers' flexing meta motions)."""
    x = gist.initial_parameters()
    for m, sl in zip(gist.motions, gist.slices(), strict=True):
        x[sl][1:] = [1.0, 0.9] if (m.finger != "TH" and m.variation[0] > 0) else 0.0
    return x


def make_trial(kind: str, options: dict):
    """``(trial, run)``: the trial and ``run() -> outcome`` of the stroke (a floor's
    ``run() -> wall s``)."""
    kind, _, floor = kind.partition(":")
    if kind == "station":
        return None, _station_run(floor, options)
    if floor:
        return _make_floor(kind, floor, options)
    if kind == "screw_cap":
        from handle_drake.apps.inhand.screw_cap import ScrewCapTask, ScrewCapTrial

        trial = ScrewCapTrial(ScrewCapTask(**options))
        x = stroke(trial.gist)
        trial._build()
        return trial, lambda: trial.evaluate(x, early_stop=False)
    if kind == "inhand":
        from handle_drake.apps.inhand.task import InHandTask, InHandTrial

        trial = InHandTrial(InHandTask(**options))
        x = stroke(trial.gist)
        trial._build()
        return trial, lambda: trial.evaluate(x)
    raise ValueError(f"kind: expected screw_cap or inhand, got {kind!r}")


def _make_floor(kind: str, floor: str, options: dict):
    import floors

    trial, _ = make_trial(kind, options)
    x = stroke(trial.gist)
    if (kind, floor) == ("screw_cap", "bare"):
        return trial, floors.screw_cap_bare(trial, x)[0]
    if kind == "inhand" and floor in ("bare", "replay"):
        outcome = trial.evaluate(x)
        sim = trial.config.total_time + (trial.config.reverse_time
                                         if outcome.survived_reversal is not None else 0.0)
        if floor == "bare":
            return trial, floors.inhand_bare(trial, x, sim)
        return trial, floors.inhand_replay(trial, x, sim)[0]
    raise ValueError(f"kind: expected screw_cap:bare, inhand:bare or inhand:replay, got "
                     f"{kind}:{floor}")


def _station_run(which: str, options: dict):
    """``run()`` of one case of ``bench_station`` (the 2 s demo grasp, 1 ms, point contact):
    ``demo`` the station as the demo builds it, ``replay`` the bare plant on its own
    frames, ``model`` the bare plant on its script, ``baseline`` the station with the
    tactile sensor and drivers of git revision ``options["revision"]``
    (``bench_station._baseline_station_case``)."""
    sys.path.insert(0, str(ROOT / "benchmarks"))
    import bench_station

    if which == "demo":
        case = bench_station._station_case(*bench_station.STATION_CASES[0])
    elif which == "replay":
        case = bench_station._replay_case()[0]
    elif which == "model":
        case = bench_station._plant_case("model")
    elif which == "baseline":
        case = bench_station._baseline_station_case(options["revision"])
    else:
        raise ValueError(f"kind: expected station:demo, station:replay, station:model or "
                         f"station:baseline, got station:{which}")
    return case.run_once


def outcome_dict(outcome) -> dict:
    d = outcome.as_dict()
    d.pop("wall_time", None)
    return json.loads(json.dumps(d, default=float))


def source_tree(revision: str | None) -> str:
    """A folder whose ``handle_drake`` (with its models and scenarios) is that of git
    ``revision`` (extracted into a temporary folder); None: this checkout."""
    if revision is None:
        return str(ROOT)
    folder = tempfile.mkdtemp(prefix=f"baseline-{revision}-")
    archive = subprocess.run(["git", "archive", revision, "handle_drake", "models",
                              "diagrams"], cwd=ROOT, capture_output=True, check=True).stdout
    path = Path(folder) / "tree.tar"
    path.write_bytes(archive)
    with tarfile.open(path) as tar:
        tar.extractall(folder, filter="data")
    return folder


class BaselineTrial:
    """The trial of git revision ``revision`` (None: this checkout, as it is) in a worker
    process (its ``handle_drake`` extracted from git); :meth:`run` times one evaluation
    there. Time both sides in workers: on a loaded machine the scheduler favours a process
    that has been waiting, which biases a worker against the benchmark's own process.
    :meth:`restart` replaces the process by a new one (same tree): one process ran the
    same code 6.7 % slower than another (two workers of one tree, paired over 7 rounds),
    so a benchmark restarts its workers every round (``speed.rounds``)."""

    def __init__(self, revision: str | None, kind: str, options: dict):
        self.revision, self._kind, self._options = revision, kind, options
        self._dir = source_tree(revision)
        self._start()

    def _start(self) -> None:
        env = {**os.environ, "PYTHONPATH": self._dir, "OPENBLAS_NUM_THREADS": "1"}
        self._process = subprocess.Popen(
            [sys.executable, str(Path(__file__).resolve()), self._kind,
             json.dumps(self._options)],
            stdin=subprocess.PIPE, stdout=subprocess.PIPE, text=True, env=env, cwd=self._dir)
        line = self._process.stdout.readline().strip()
        if line != "ready":
            raise RuntimeError(f"baseline worker at {self.revision}: {line!r}")

    def restart(self) -> None:
        """A new worker process in place of this one (built and warmed up the same way)."""
        self.close()
        self._start()

    def run(self) -> tuple[float, float, dict]:
        """(wall s of the trial, CPU s of the worker, outcome)."""
        self._process.stdin.write("run\n")
        self._process.stdin.flush()
        reply = json.loads(self._process.stdout.readline())
        return reply["wall"], reply["cpu"], reply["outcome"]

    def close(self) -> None:
        self._process.stdin.close()
        self._process.wait(timeout=30)


def main() -> int:
    import time

    if sys.argv[1] == "--count":  # instructions.py: the counted runs inside starmap
        import itertools

        _, run = make_trial(sys.argv[2], json.loads(sys.argv[3]))
        run()  # warm-up, not counted (first-run allocations)
        list(itertools.starmap(run, [()] * int(sys.argv[4])))
        print("counted", flush=True)
        return 0
    kind, options = sys.argv[1], json.loads(sys.argv[2])
    _, run = make_trial(kind, options)
    run()
    print("ready", flush=True)
    for line in sys.stdin:
        if line.strip() != "run":
            break
        cpu = time.process_time()
        outcome = run()
        if isinstance(outcome, float):  # a floor: its wall time, no outcome
            reply = {"wall": outcome, "cpu": time.process_time() - cpu, "outcome": None}
        else:
            reply = {"wall": outcome.wall_time, "cpu": time.process_time() - cpu,
                     "outcome": outcome_dict(outcome)}
        print(json.dumps(reply), flush=True)
    return 0


if __name__ == "__main__":
    sys.exit(main())
