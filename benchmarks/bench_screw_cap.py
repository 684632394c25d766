"""The screw cap (report Fig. 32): base rate, the optimiser table and the re-simulated best.

1. ``--base-rate N``: N uniformly random parameter vectors in the action-gist
   box (``run_inhand(..., "random")`` without its stop, so all N run; logged in
   the SQLite ``--db``, resumable): the share reaching the target (the cap
   turned >= ``--target-deg`` by its encoder, palm never touching, all checks).
2. ``--table``: ipso (Algorithm 2), pso, cmaes and random search, ``--seeds``
   each, every run until a trial reaches the target or ``--budget`` trials;
   plus the demonstration's own parameters (one trial). Per optimiser: median
   trials to the target (a run that did not reach it counts as the budget +
   1 and is listed as not reached), median best turn and score at the budget.
3. ``--resimulate``: every run's best trial re-simulated from its logged
   scenario YAML alone by ``handle_drake.apps.inhand.screw_cap.simulate_scenario``
   (a separate build that reads the cap joint from the plant).

4. ``--speed ROUNDS [--baseline REV]``: a trial against the bare plant on the same frames
   and simulated time; with ``--baseline`` the trial of git revision REV and this tree's,
   each in a worker process (``benchmarks/support/trial_worker.py``), outcome checked
   identical, after/before paired by round.

Run: ``python benchmarks/bench_screw_cap.py --base-rate 200 --table --seeds 0 1 2 3 4
--budget 60 --resimulate``; writes ``benchmarks/results/screw_cap.json`` and prints
markdown tables (``docs/results/inhand.md``).
"""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path

from handle_drake.base.blas import pin_blas  # noqa: E402 - light: loads neither numpy nor Drake

pin_blas(force=False)

import numpy as np  # noqa: E402

from handle_drake.apps.inhand.experiment import EVALUATION_SEEDS, run_inhand  # noqa: E402
from handle_drake.apps.inhand.screw_cap import (  # noqa: E402
    DEFAULT_PLACEMENT,
    FOUR_FINGER_GRIP,
    FOUR_FINGER_TURN,
    FOUR_FINGER_TURN_MOTION,
    PLACEMENTS,
    TWO_STROKES,
    ScrewCapTask,
    ScrewCapTrial,
    contact_forces,
    contact_summary,
    four_finger_turn_motion,
    fresh_success,
    simulate_scenario,
)
from handle_drake.base.results import ResultsRun, add_page_arguments, table_rows  # noqa: E402
from handle_drake.learning.log import TrialLog  # noqa: E402

RESULTS = Path(__file__).parent / "results" / "screw_cap.json"
OPTIMIZERS = ("ipso", "ipso-gist", "ipso-report", "ipso-restart", "pso", "cmaes", "random")
# the fingertip cylinder's targets: the 60 deg pinch (default) and TWO_STROKES
FINGERTIP = {"pinch": {}, "two-strokes": {k: v for k, v in TWO_STROKES.items() if k != "free"}}


def base_rate(n, seed, db, workers, options) -> dict:
    # random search with no stop: all n trials run
    from handle_drake.apps.inhand.experiment import _config
    from handle_drake.apps.inhand.screw_cap import scenario_fingerprint
    from handle_drake.learning.loop import TrialRunner
    from handle_drake.learning.optim.population import StoppingRandomSearch

    trial = ScrewCapTrial(ScrewCapTask(**options))
    config = _config(trial, "random-nostop", 1)
    run_id = f"base-rate-{trial.name}-seed{seed}-" + scenario_fingerprint(
        json.dumps(config, sort_keys=True))
    with TrialLog(db) as log:
        log.open_run(run_id, "random", trial.bounds, seed, trial.name, config)
        opt = StoppingRandomSearch(trial.bounds, seed, stop_score=None)
        TrialRunner(trial, opt, log, run_id, workers=workers, batch_size=workers,
                    progress=False).run(n)
        records = [r for r in log.trials(run_id) if r.status == "done"]
    turns = np.array([r.contacts["turn_deg"] for r in records])
    reached = np.array([bool(r.contacts["reached_target"]) for r in records])
    return {"trials": len(records), "reached": int(reached.sum()),
            "base_rate": float(reached.mean()) if records else None,
            "share_turn_ge_target": float(np.mean(turns >= trial.config.target_deg)),
            "turn_deg_quantiles": np.quantile(turns, [0.1, 0.5, 0.9, 1.0]).round(1).tolist(),
            "run_id": run_id}


def base_rate_curve(n, seed, targets, options) -> dict:
    """The base rate at several targets from one set of ``n`` uniform draws in the box (numpy
    ``seed``), each run to its end at the task's own target: reached at target T when every
    check passed (gripped, turn >= T x its fraction - tolerance, read at the check's sample),
    the final turn >= T and neither palm nor welded body leaned on. The rule is the trial's;
    at the task's own target the count is checked against the trial's ``reached_target``."""
    from scipy.stats import beta

    trial = ScrewCapTrial(ScrewCapTask(**options))
    c, rec, gripped = trial.config, [], trial._gripped

    def spy(st, t, *a):
        rec.append((float(t), bool(g := gripped(st, t, *a))))
        return g

    trial._gripped = spy
    b, rng = trial.bounds, np.random.default_rng(seed)
    checks, fractions = c.check_times(), c.benchmark_fractions()
    draws = []
    for _ in range(n):
        x = b[:, 0] + rng.random(len(b)) * (b[:, 1] - b[:, 0])
        rec.clear()
        o = trial.evaluate(x, early_stop=False)
        ts = np.array([r[0] for r in rec])
        at = [int(np.argmin(abs(ts - t))) for t in checks]
        draws.append((o, [o.turn_deg_series[k] for k in at], [rec[k][1] for k in at]))

    def reached(o, turns, grips, target):
        return bool(all(g and turn >= target * f - c.tolerance_deg
                        for g, turn, f in zip(grips, turns, fractions, strict=True))
                    and o.turn_deg >= target and not o.palm_touched and not o.leaned_on_welded)

    own = sum(reached(*d, c.target_deg) for d in draws)
    assert own == sum(d[0].reached_target for d in draws), "the curve's rule is not the trial's"
    rows = []
    for target in targets:
        k = sum(reached(*d, target) for d in draws)
        rows.append({"target_deg": target, "draws": n, "reached": k, "base_rate": k / n,
                     "upper_95_one_sided": float(beta.ppf(0.95, k + 1, n - k))})
        print(f"| {target:g} | {n} | {k} | {100 * k / n:.2f} % | "
              f"{100 * rows[-1]['upper_95_one_sided']:.2f} % |", flush=True)
    return {"seed": seed, "rows": rows,
            "turn_deg_quantiles": np.quantile([d[0].turn_deg for d in draws],
                                              [0.1, 0.5, 0.9, 1.0]).round(1).tolist()}


def table(seeds, budget, db, workers, options, optimizers=OPTIMIZERS, random_budget=None,
          fresh=0) -> dict:
    """``random_budget``: random search's budget (default 3 x ``budget``, issue 45 item 4);
    ``fresh``: each run's best trial that reached the target tried on that many fresh
    perturbed physics (``screw_cap.fresh_success``: never used while learning)."""
    rows = {}
    best_trials = []
    by_optimizer = {optimizer: [] for optimizer in optimizers}
    budgets = {o: (3 * budget if random_budget is None else random_budget)
               if o == "random" else budget for o in optimizers}
    for seed in seeds:  # seed-major: an interrupted table has every optimiser's first seeds
        for optimizer in optimizers:
            task = "fingertip_cylinder" if options["free"] else "screw_cap"
            run = run_inhand(task, optimizer, budgets[optimizer], workers, seed, db,
                             progress=False,
                             **{k: v for k, v in options.items() if k != "free"})
            s = run.summary()
            row = {"seed": seed, "trials": s["done"], "to_target": s["trials_to_target"],
                   "best_turn_deg": s["best_held_rotation_deg"], "best_score": s["best_score"],
                   "run_id": run.run_id}
            done = [r for r in run.records if r.status == "done"]
            best = max(done, key=lambda r: r.metric)
            best_trials.append((run.run_id, best.index, best.scenario, best.contacts["turn_deg"]))
            if fresh and s["trials_to_target"]:
                f = fresh_success(run.trial.config, best.parameters, fresh)
                row.update(fresh_success=f["success"], fresh_turns=f["turns"])
            by_optimizer[optimizer].append(row)
            print(f"{optimizer} seed {seed}: {s['done']} trials, to target "
                  f"{s['trials_to_target']}, best turn {s['best_held_rotation_deg']:.1f} deg"
                  + (f", best trial over {fresh} fresh perturbations: reached in "
                     f"{100 * row['fresh_success']:.0f} %" if "fresh_success" in row else ""),
                  flush=True)
    for optimizer, runs in by_optimizer.items():
        to = [r["to_target"] if r["to_target"] else budgets[optimizer] + 1 for r in runs]
        rows[optimizer] = {
            "runs": runs, "median_trials_to_target": float(np.median(to)),
            "reached": sum(bool(r["to_target"]) for r in runs),
            "median_best_turn_deg": float(np.median([r["best_turn_deg"] for r in runs])),
            "median_best_score": float(np.median([r["best_score"] for r in runs]))}
    trial = ScrewCapTrial(ScrewCapTask(**options))
    demo = trial.evaluate(trial.gist.initial_parameters(), early_stop=False)
    rows["demonstration"] = {"turn_deg": demo.turn_deg, "score": demo.score,
                             "reached": demo.reached_target}
    return {"rows": rows, "best_trials": best_trials}


def resimulate(best_trials) -> list:
    out = []
    for run_id, index, scenario, logged in best_trials:
        truth = simulate_scenario(scenario)
        out.append({"run_id": run_id, "trial": index, "logged_turn_deg": logged,
                    "resimulated_turn_deg": truth["turn_deg"],
                    "palm_force_max": truth["palm_force_max"],
                    "survived_reversal": truth.get("survived_reversal")})
        print(f"{run_id} trial {index}: logged {logged:.1f} deg, re-simulated "
              f"{truth['turn_deg']:.1f} deg, palm force max {truth['palm_force_max']:.2f} N, "
              f"survived reversal {truth.get('survived_reversal')}", flush=True)
    return out


# Four-finger grasp designs tried for issue 35's grip (thumb, first, middle and ring distal
# phalanges on the cap in the settled grasp, palm 0 N), each with hand-written motions in the
# gist's box: ``--designs`` measures the turn and, from the contact results, each digit's
# normal force and torque about the cap's axis (docs/results/inhand.md, 2026-11-27 issue-35g).
_SQUEEZE = dict(FOUR_FINGER_GRIP)
_YAWED = dict(cap_position=(0.3936, -0.0276, 0.0726), cap_diameter=0.04,
              cap_axis_yaw_deg=-24.0, grasp_closure=(("THJ5", 0.3), ("FFJ2", 0.15),
                                                     ("MFJ2", 0.15), ("RFJ2", 0.15)))
_DISTAL = dict(cap_position=(0.383, -0.03, 0.068), cap_diameter=0.04, cap_length=0.08,
               grasp_closure=(("THJ5", 0.3), ("FFJ2", 0.3), ("MFJ2", 0.3), ("RFJ2", 0.3)))
_HOOK = dict(FOUR_FINGER_TURN)
# (name, task settings, motion name, motion: thumb flex (THJ5, THJ2, THJ1), thumb release,
# its start, fingers' flex (J3, J2), fingers' release, its start; None: the gist's start)
DESIGNS = [
    ("one-gait (reference)", {}, "fingers flex", ((0, 0, 0), (0, 0, 0), None,
                                                  (1.0, 0.9), (0, 0), None)),
    ("squeeze (FOUR_FINGER_GRIP)", _SQUEEZE, "all flex", ((0.4, 0.4, 0.4), (0, 0, 0), None,
                                                         (1.0, 0.9), (0, 0), None)),
    ("squeeze (FOUR_FINGER_GRIP)", _SQUEEZE, "fingers flex, thumb releases",
     ((0, 0, 0), (0.4, 0.4, 0.4), 0.2, (1.0, 0.9), (0, 0), None)),
    ("distal, axis yawed -24 deg", _YAWED, "all flex", ((0.4, 0.4, 0.4), (0, 0, 0), None,
                                                        (1.0, 0.9), (0, 0), None)),
    ("distal, axis yawed -24 deg", _YAWED, "fingers flex, thumb releases",
     ((0, 0, 0), (0.4, 0.4, 0.4), 0.2, (1.0, 0.9), (0, 0), None)),
    ("distal, axis along the flexion axes", _DISTAL, "fingers flex, thumb releases",
     ((0, 0, 0), (0.4, 0.4, 0.4), 0.2, (1.0, 0.9), (0, 0), None)),
    ("distal, axis along the flexion axes", _DISTAL, "fingers flex (J3 1.5, J2 0.3), thumb "
     "releases", ((0, 0, 0), (0.4, 0.4, 0.4), 0.2, (1.5, 0.3), (0, 0), None)),
    ("hook (fingers curled round)", _HOOK, "all flex (J3)", ((0.4, 0.4, 0.4), (0, 0, 0), None,
                                                            (1.0, 0.3), (0, 0), None)),
    ("hook (fingers curled round)", _HOOK, "fingers flex, thumb releases",
     ((0, 0, 0), (0.4, 0.4, 0.4), 0.2, (1.0, 0.3), (0, 0), None)),
    ("hook (fingers curled round)", _HOOK, "thumb flexes, fingers release",
     ((0.4, 0.4, 0.4), (0, 0, 0), None, (0, 0), (0.6, 0.6), 0.2)),
    ("hook (fingers curled round)", _HOOK, "thumb flexes (THJ5 1.5), fingers release",
     ((1.5, 0.3, 0.3), (0, 0, 0), None, (0, 0), (0.3, 0.3), 0.2)),
    ("hook = FOUR_FINGER_TURN", _HOOK, "FOUR_FINGER_TURN_MOTION: FF, MF J2 flex; RF J3 "
     "flex, then extension; thumb still", FOUR_FINGER_TURN_MOTION),
]
DIGITS = ("th", "ff", "mf", "rf")


def design_motion(trial, motion) -> np.ndarray:
    """A gist parameter vector from a DESIGNS motion (magnitudes per meta motion, in the
    gist's directions; starts as demonstrated unless given; a dict: per finger's meta
    motion, as :func:`four_finger_turn_motion`)."""
    if isinstance(motion, dict):
        return four_finger_turn_motion(trial.gist, motion)
    th_flex, th_release, th_start, f_flex, f_release, f_start = motion
    x = trial.gist.initial_parameters()
    for m, sl in zip(trial.gist.motions, trial.gist.slices(), strict=True):
        flex = m.variation[0] > 0
        if m.finger == "TH":
            x[sl][1:] = th_flex if flex else th_release
            start = None if flex else th_start
        else:
            x[sl][1:] = f_flex if flex else f_release
            start = None if flex else f_start
        if start is not None:
            x[sl][0] = start
    return x


def designs() -> list:
    """Each DESIGNS row run to its end (the trial's own build and settled grasp), sampled
    every 25 ms: the settled digits on the cap, the encoder's turn, the part of it made
    while all four digits touched the cap, the palm's largest force and, per digit, its
    mean normal force (N) and torque about the cap's axis (mN m, + drives the turn)
    over the samples of the stroke (0.15-0.8 s) where it touches the cap."""
    rows = []
    for name, settings, motion_name, motion in DESIGNS:
        trial = ScrewCapTrial(ScrewCapTask(**settings))
        x = design_motion(trial, motion)
        built = trial._build()
        plant = built["plant"]
        settled = contact_summary(plant, plant.GetMyContextFromRoot(built["settled"]), built)
        plant_context = trial._reset(built, x)
        simulator = built["simulator"]
        simulator.Initialize()
        joint = built["joint"]
        q0 = joint.get_angle(plant_context)
        turn, four, palm, per = 0.0, 0.0, 0.0, {d: [] for d in DIGITS}
        for t in trial.config.sample_times():
            simulator.AdvanceTo(float(t))
            now = float(np.degrees(joint.get_angle(plant_context) - q0))
            forces = contact_forces(plant, plant_context, built)
            on = {b[:2] for b in forces} & set(DIGITS)
            if len(on) == 4:
                four += now - turn
            turn = now
            palm = max(palm, contact_summary(plant, plant_context, built)["palm_force"])
            if 0.15 <= t <= 0.8:
                for d in DIGITS:
                    fn = sum(v[0] for b, v in forces.items() if b.startswith(d))
                    if fn > 0:
                        per[d].append((fn, sum(v[2] for b, v in forces.items()
                                               if b.startswith(d))))
        digits = "".join(d.upper() for d in DIGITS
                         if any(b.startswith(d) for b in settled["touching"]))
        row = {"design": name, "motion": motion_name, "settled_digits": digits,
               "settled_palm_N": settled["palm_force"], "turn_deg": round(turn, 1),
               "turn_4_digits_deg": round(four, 1), "palm_max_N": round(palm, 2)}
        for d in DIGITS:
            a = np.array(per[d]) if per[d] else np.zeros((1, 2))
            row[f"{d}_N_mNm"] = f"{a[:, 0].mean():.0f} / {1e3 * a[:, 1].mean():+.0f}"
        rows.append(row)
        print(" | ".join(str(v) for v in row.values()), flush=True)
    return rows


def speed(rounds: int, options, baseline: str | None = None) -> dict:
    """A screw-cap trial against the bare plant on the same frames from the same state
    (and the same simulated time: the fingertip cylinder's trial runs its 0.5 s of reversed
    weight, which the bare plant then simulates too, holding the last frame), in the
    benchmark's process and each in a worker process of its own. With ``baseline``: the
    same trial at that git revision, in a worker process, every round (its outcome checked
    equal to this tree's)."""
    sys.path.insert(0, str(Path(__file__).parent / "support"))  # helpers, not benchmarks
    from floors import screw_cap_bare
    from speed import OWN, speed_table
    from trial_worker import BaselineTrial, outcome_dict, stroke

    trial = ScrewCapTrial(ScrewCapTask(**options))
    x = stroke(trial.gist)  # the hand-written stroke
    run_bare, total, mine = screw_cap_bare(trial, x)  # mine: the trial's outcome of x

    cases = {"trial (reset, samples, checks)": lambda: trial.evaluate(x, early_stop=False)
             .wall_time,
             # the trial as before: Python hand driver per step, contact results per sample
             "trial, driver + contact results": lambda: trial.evaluate(
                 x, early_stop=False, contact_results=True, driver=True).wall_time,
             "bare plant, same frames": run_bare}
    workers = {"trial (reset, samples, checks)" + OWN: BaselineTrial(None, "screw_cap", options),
               "bare plant, same frames" + OWN: BaselineTrial(None, "screw_cap:bare", options)}
    return speed_table(cases, workers, rounds, trial="trial (reset, samples, checks)",
                       floor="bare plant, same frames", sim_time=total, kind="screw_cap",
                       options=options, baseline=baseline, outcome=outcome_dict(mine))[0]


def summarize(db, budget, resim: bool = False, more=()) -> dict:
    """The table from whatever the trial logs hold (also of an interrupted table run):
    ``db`` and the logs ``more``. Random search's trials are uniform draws: their share
    that reached the target is reported as the base rate (``base_rate_from_random``)."""
    rows, resimulated = {}, []
    for path in (db, *more):
        _summarize_log(path, budget, resim, rows)
    return _summary_table(rows, budget, resimulated)


def _summarize_log(db, budget, resim, rows) -> None:
    with TrialLog(db) as log:
        for info in log.runs():
            if info.run_id.startswith("base-rate"):
                continue
            records = [r for r in log.trials(info.run_id) if r.status == "done"][:budget]
            if not records:
                continue
            reached = [r.index + 1 for r in records if r.contacts.get("reached_target")]
            best = max(records, key=lambda r: r.metric)
            run = {"seed": info.seed, "trials": len(records),
                   "to_target": min(reached) if reached else None,
                   "best_turn_deg": max(r.contacts["turn_deg"] for r in records
                                        if r.contacts.get("completed")) if any(
                       r.contacts.get("completed") for r in records) else None,
                   "best_score": best.metric, "best_trial": best.index,
                   "best_trial_turn_deg": best.contacts["turn_deg"], "run_id": info.run_id}
            if resim:
                truth = simulate_scenario(best.scenario)
                run["resimulated_turn_deg"] = truth["turn_deg"]
                run["resimulated_palm_force_max"] = truth["palm_force_max"]
                if "survived_reversal" in truth:
                    run["resimulated_survived_reversal"] = truth["survived_reversal"]
                print(f"{info.run_id} best trial {best.index} (score {best.metric:.3f}): "
                      f"logged turn {best.contacts['turn_deg']:.1f} deg, re-simulated "
                      f"{truth['turn_deg']:.1f} deg, palm force max "
                      f"{truth['palm_force_max']:.2f} N, survives reversed weight "
                      f"{truth.get('survived_reversal')}", flush=True)
            rows.setdefault(info.strategy, []).append(run)


def _summary_table(rows, budget, resimulated) -> dict:
    out = {}
    for optimizer, runs in rows.items():
        # not reached: its own budget + 1 (a run that did not reach the target ran to its
        # budget: its trials, at most --budget)
        to = [r["to_target"] if r["to_target"] else r["trials"] + 1 for r in runs]
        out[optimizer] = {"runs": runs, "median_trials_to_target": float(np.median(to)),
                          "reached": sum(bool(r["to_target"]) for r in runs),
                          "median_best_score": float(np.median([r["best_score"]
                                                                 for r in runs]))}
        line = ", ".join(f"seed {r['seed']}: {r['to_target'] or '-'}/{r['trials']}"
                         for r in runs)
        out[optimizer].update(n_runs=len(runs), per_seed=line)
        print(f"| {optimizer} | {out[optimizer]['reached']}/{len(runs)} | "
              f"{out[optimizer]['median_trials_to_target']:g} | "
              f"{out[optimizer]['median_best_score']:.2f} | {line} |", flush=True)
    draws = sum(r["trials"] for r in rows.get("random", []))
    hits = sum(bool(r["to_target"]) for r in rows.get("random", []))
    base = {"draws": draws, "reached": hits, "base_rate": hits / draws if draws else None}
    print(f"base rate (random search's uniform draws): {hits}/{draws}", flush=True)
    return {"rows": out, "resimulated": resimulated, "base_rate_from_random": base}


def diagnose(db, batch: int = 10) -> dict:
    """Per run of the log and per iteration (``batch`` trials): the swarm's spread (mean
    per-dimension standard deviation of the trials' parameters, as a share of the box),
    the scores' min / median / max and how many distinct scores (to 3 decimals) the
    iteration's trials got, and the largest turn of a trial that passed 3 checks."""
    out = {}
    with TrialLog(db) as log:
        for info in log.runs():
            records = [r for r in log.trials(info.run_id) if r.status == "done"]
            if not records:
                continue
            b = np.asarray(info.bounds, dtype=float)
            width = np.where(b[:, 1] > b[:, 0], b[:, 1] - b[:, 0], 1.0)
            U = (np.array([r.parameters for r in records]) - b[:, 0]) / width
            f = np.array([r.metric for r in records])
            rows = []
            for start in range(0, len(records), batch):
                sl = slice(start, start + batch)
                done3 = [r.contacts["turn_deg"] for r in records[sl]
                         if r.contacts.get("checks_passed", 0) >= 3]
                rows.append({"iteration": start // batch + 1,
                             "spread": float(U[sl].std(axis=0).mean()),
                             "score_min_median_max": [float(f[sl].min()),
                                                      float(np.median(f[sl])),
                                                      float(f[sl].max())],
                             "distinct_scores": int(np.unique(np.round(f[sl], 3)).size),
                             "trials": int(f[sl].size),
                             "max_turn_3_checks": max(done3) if done3 else None})
            out[info.run_id] = rows
            print(f"{info.run_id}:", flush=True)
            for r in rows:
                lo, med, hi = r["score_min_median_max"]
                print(f"  it {r['iteration']:2d}: spread {r['spread']:.3f}  score "
                      f"{lo:.2f}/{med:.2f}/{hi:.2f}  distinct {r['distinct_scores']}/"
                      f"{r['trials']}  turn (3 checks) {r['max_turn_3_checks']}", flush=True)
    return out


def figures(db, task, options, directory, html: bool = True) -> dict:
    """Figure 34 (best score per iteration, every run of the log) and an HTML replay of the
    best trial of all runs (re-run from its parameters with a Meshcat recording)."""
    from handle_drake.apps.inhand.experiment import InHandRun, plot_learning_curve, replay_best

    trial = ScrewCapTrial(ScrewCapTask(**options))
    runs = []
    with TrialLog(db) as log:
        for info in log.runs():
            if info.run_id.startswith("base-rate"):
                continue
            records = [r for r in log.trials(info.run_id)]
            n = int((info.config or {}).get("n_particles", 10))
            runs.append(InHandRun(info.run_id, Path(db), trial, info.strategy, n, info.seed,
                                  records))
    directory = Path(directory)
    directory.mkdir(parents=True, exist_ok=True)
    png = plot_learning_curve(runs, directory / f"{task}_learning_curve.png",
                              title=f"{trial.name}: best score per iteration")
    out = {"learning_curve": str(png)}
    if html and runs:
        best_run = max(runs, key=lambda r: max((t.metric for t in r.records
                                                if t.status == "done"), default=-1))
        page = directory / f"{task}_best.html"
        logged, outcome = replay_best(best_run, page)
        out.update(html=str(page), run_id=best_run.run_id, logged_score=logged,
                   replayed_score=outcome.score, turn_deg=outcome.turn_deg)
        print(f"replay: {page} ({best_run.run_id}, score {outcome.score:.3f}, logged "
              f"{logged:.3f}, turn {outcome.turn_deg:.1f} deg)", flush=True)
    return out


def main(argv=None) -> int:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--base-rate", type=int, default=0, metavar="N")
    p.add_argument("--table", action="store_true")
    p.add_argument("--base-rate-curve", type=int, default=0, metavar="N",
                   help="N uniform draws (numpy seed 4545) run to their end: the base rate "
                        "at each of --curve-targets (and its one-sided 95 %% upper bound)")
    p.add_argument("--curve-targets", nargs="+", type=float,
                   default=[90.0, 180.0, 240.0, 270.0, 300.0, 360.0], metavar="DEG")
    p.add_argument("--resimulate", action="store_true")
    p.add_argument("--speed", type=int, default=0, metavar="ROUNDS")
    p.add_argument("--designs", action="store_true",
                   help="the four-finger grasp designs tried (DESIGNS): turn, the turn made "
                        "with all four digits on the cap, each digit's force and torque")
    p.add_argument("--baseline", default=None, metavar="REV",
                   help="with --speed: also time the trial of git revision REV (a worker "
                        "process on its handle_drake), every round, its outcome checked")
    p.add_argument("--figures", type=Path, default=None, metavar="DIR",
                   help="learning curve of every run in --db and the best trial's HTML replay")
    p.add_argument("--diagnose", action="store_true",
                   help="per run in --db and per iteration: the swarm's spread and the "
                        "scores' distribution")
    p.add_argument("--summarize", action="store_true",
                   help="the table from the trial log as it is (with --resimulate: re-simulate "
                        "each run's best trial from its logged scenario)")
    p.add_argument("--seeds", nargs="+", type=int, default=[0, 1, 2, 3, 4])
    p.add_argument("--evaluation", action="store_true",
                   help="run on the evaluation seeds (experiment.EVALUATION_SEEDS) instead of "
                        "--seeds: never used for tuning")
    p.add_argument("--optimizers", nargs="+", choices=OPTIMIZERS, default=list(OPTIMIZERS))
    p.add_argument("--budget", type=int, default=60)
    p.add_argument("--random-budget", type=int, default=None, metavar="N",
                   help="--table: random search's budget (default 3 x --budget)")
    p.add_argument("--robust", type=int, default=0, metavar="K",
                   help="score each trial by its worst over K perturbed physics drawn per "
                        "trial (ScrewCapTask.robust_k; 0: the nominal physics)")
    p.add_argument("--fresh", type=int, default=0, metavar="N",
                   help="--table: each run's best trial that reached the target tried on N "
                        "fresh perturbed physics never used while learning")
    p.add_argument("--task", choices=("screw_cap", "fingertip_cylinder"), default="screw_cap")
    p.add_argument("--target-deg", type=float, default=None,
                   help="default: 90 (screw cap), 60 (fingertip cylinder)")
    p.add_argument("--gaits", type=int, default=None, help="default: 1 (the placement's)")
    p.add_argument("--benchmark", nargs="+", type=float, default=None, metavar="F",
                   help="the turn / target required at each check (ScrewCapTask.benchmark; "
                        "default (0, 0.05, 0.3, 1) for one gait, k/K for more)")
    p.add_argument("--placement", choices=sorted(PLACEMENTS), default=None,
                   help="the screw cap's placement: clear (the default, as `handle-drake "
                        "inhand`: CLEAR, nothing wedged against the welded bottle, 1 ms); the "
                        "older ones, a finger wedged against the bottle: one-gait (ONE_GAIT), "
                        "four-finger (FOUR_FINGER_GRIP), regrasp (REGRASP_GAITS: 5 gaits, 360 "
                        "deg), four-finger-turn (FOUR_FINGER_TURN); clear-gaits "
                        "(CLEAR_GAITS: clear's cap, one learned gait repeated 3 times, 360 deg)")
    p.add_argument("--grip-digits", type=int, default=None, choices=range(1, 6),
                   metavar="N", help="screw_cap: digits that must each touch the cap within "
                   "the contact window for a check (ScrewCapTask.grip_digits; default 1)")
    p.add_argument("--fingertip", choices=sorted(FINGERTIP), default=None,
                   help="the fingertip cylinder's target: two-strokes (the default, as "
                        "`handle-drake inhand`: TWO_STROKES, 100 deg in two strokes, the turn "
                        "counted only while held) or pinch (60 deg in one stroke; the tables "
                        "before 2026-11-27 evening)")
    p.add_argument("--workers", type=int, default=1)
    p.add_argument("--db", type=Path, default=Path("out/inhand/screw_cap.sqlite"))
    p.add_argument("--more-db", nargs="+", type=Path, default=[], metavar="DB",
                   help="--summarize: trial logs read after --db (e.g. each optimiser's own)")
    p.add_argument("--out", type=Path, default=RESULTS)
    add_page_arguments(p, "inhand")
    args = p.parse_args(argv)
    if args.evaluation:
        args.seeds = list(EVALUATION_SEEDS)
    if args.placement is not None and args.task != "screw_cap":
        p.error("--placement: only with --task screw_cap")
    if args.placement is None:
        args.placement = DEFAULT_PLACEMENT
    preset = PLACEMENTS[args.placement] if args.task == "screw_cap" else {}
    if args.fingertip is not None and args.task != "fingertip_cylinder":
        p.error("--fingertip: only with --task fingertip_cylinder")
    if args.task == "fingertip_cylinder" and args.fingertip is None:
        args.fingertip = "two-strokes"
    if args.task == "fingertip_cylinder":
        preset = FINGERTIP[args.fingertip]
    # a section of the page each: the screw cap's runs, the fingertip cylinder's, speed
    section = " ".join(([f"--task {args.task}"] if args.task != "screw_cap" else [])
                       + (["--speed"] if args.speed else [])) or None
    # the published budget of each section: --speed's rounds; the screw cap's seeds and
    # trials per run; the fingertip cylinder's trials per run
    published = ({"speed": 7} if args.speed else {"budget": 450}
                 if args.task == "fingertip_cylinder" else {"seeds": 3, "budget": 100})
    results_run = ResultsRun(f"In-hand {args.task}: base rate, optimisers and speed", args,
                             section=section, published=published)
    if args.target_deg is None:
        args.target_deg = preset.get("target_deg", 90.0 if args.task == "screw_cap" else 60.0)
    if args.gaits is None:
        args.gaits = preset.get("n_gaits", 1)
    options = {**preset, "target_deg": args.target_deg, "n_gaits": args.gaits,
               "free": args.task == "fingertip_cylinder"}
    if args.grip_digits is not None:
        options["grip_digits"] = args.grip_digits
    for flag, value in (("--robust", args.robust), ("--fresh", args.fresh),
                        ("--base-rate-curve", args.base_rate_curve),
                        ("--random-budget", args.random_budget or 0)):
        if not 0 <= value <= 1000:
            p.error(f"{flag}: expected an integer in [0, 1000], got {value}")
    if args.robust:
        options["robust_k"] = args.robust
    if args.benchmark is not None:
        if len(args.benchmark) != 4 or not all(0 <= f <= 1 for f in args.benchmark):
            p.error(f"--benchmark: expected 4 fractions in [0, 1], got {args.benchmark}")
        options["benchmark"] = tuple(args.benchmark)
    args.db.parent.mkdir(parents=True, exist_ok=True)
    result = json.loads(args.out.read_text()) if args.out.exists() else {}
    key = f"{args.task}-target{args.target_deg:g}-gaits{args.gaits}" + (
        f"-{args.placement if args.task == 'screw_cap' else args.fingertip}" if preset else ""
    ) + (f"-grip{args.grip_digits}" if args.grip_digits not in (None, 1) else "") + (
        f"-robust{args.robust}" if args.robust else "") + (
        "-benchmark" + "_".join(f"{f:g}" for f in args.benchmark) if args.benchmark else "")
    entry = result.setdefault(key, {})
    if args.designs:
        result["four_finger_designs"] = designs()
    if args.speed:
        entry["speed"] = speed(args.speed, options, args.baseline)
    if args.figures is not None:
        entry["figures"] = figures(args.db, args.task, options, args.figures)
    if args.diagnose:
        entry["diagnosis"] = diagnose(args.db)
    if args.summarize:
        entry["summary"] = summarize(args.db, args.budget, args.resimulate, args.more_db)
    if args.base_rate_curve:
        entry["base_rate_curve"] = base_rate_curve(args.base_rate_curve, 4545,
                                                   args.curve_targets, options)
    if args.base_rate:
        entry["base_rate"] = base_rate(args.base_rate, 1000, args.db, args.workers, options)
        print(json.dumps(entry["base_rate"]), flush=True)
    if args.table:
        t = table(args.seeds, args.budget, args.db, args.workers, options, args.optimizers,
                  args.random_budget, args.fresh)
        entry.setdefault("table", {}).update(t["rows"])
        entry["budget"] = args.budget
        if args.resimulate:
            entry["resimulated"] = resimulate(t["best_trials"])
    printed = [{"task": "designs", "part": "designs", **row}
               for row in result.get("four_finger_designs", []) if args.designs]
    for part in ("speed", "base_rate", "summary", "table"):
        if part in entry:
            value = entry[part]
            if part == "summary":  # one row per optimiser, then the base rate
                value = [*table_rows(value["rows"], "optimizer"),
                         {"optimizer": "base rate (random search's draws)",
                          **value["base_rate_from_random"]}]
            printed += [{"task": key, "part": part, **row}
                        for row in table_rows(value, "case")]
    results_run.finish(printed, json.loads(json.dumps(result, default=float)), args.out)
    return 0


if __name__ == "__main__":
    sys.exit(main())
