"""Mesh objects: convex decomposition (time, pieces, fit) and trial time against the catalogue.

Side by side in one process (ratios count on a shared machine):

1. **Decomposition** of the generated torus, L-bracket and bowl
   (``handle_drake.geometry.objects.mesh_examples``) and of the catalogue mug's cup wall
   re-meshed as one closed solid of revolution: CoACD as ``mesh_objects``
   runs it (cold, into an empty cache), the cached read, and the floor, one
   qhull hull (``scipy.spatial.ConvexHull``, what a single ``Convex`` would
   be). With ``--vhacd`` also V-HACD (``vhacdx``, if importable). Fit by
   Monte Carlo in the bounding box: *coverage* = share of the mesh's volume
   inside some piece (1 is best), *excess* = volume inside pieces but outside
   the mesh, over the mesh's volume (0 is best); "inside the mesh" is the
   generalised winding number (``mesh_objects.contains``).
2. **Trial time**: one Barrett grasp trial (``GraspTrial``, 2-D offset
   space, diagram built once, median of ``--trials`` trials) on a catalogue
   object and on the same object written as a mesh file, and on the torus.
   The ratio mesh / catalogue is the cost of a mesh object in a trial.

Usage: ``python benchmarks/bench_mesh_objects.py [--quick] [--vhacd] [--trials N]``
Writes ``benchmarks/results/bench_mesh_objects.json``.
"""

from __future__ import annotations

import argparse
import os
import statistics
import tempfile
import time
from pathlib import Path

from handle_drake.base.blas import pin_blas  # noqa: E402 - light: loads neither numpy nor Drake

pin_blas(force=False)

import numpy as np  # noqa: E402
import trimesh  # noqa: E402
from scipy.spatial import ConvexHull, Delaunay, QhullError  # noqa: E402

from handle_drake.base.results import ResultsRun, add_page_arguments  # noqa: E402
from handle_drake.geometry.objects import ObjectSpec, mesh_examples  # noqa: E402
from handle_drake.geometry.objects import mesh as mesh_objects  # noqa: E402

RESULTS = Path(__file__).resolve().parent / "results"


def _cup(segments: int = 32) -> trimesh.Trimesh:
    """A mug-like cup (no handle): 8 cm wide, 8.8 cm tall, 5.6 mm wall, 6.4 mm bottom."""
    r, h, wall, bottom = 0.04, 0.088, 0.0056, 0.0064
    profile = np.array([[0, 0], [r, 0], [r, h], [r - wall, h], [r - wall, bottom], [0, bottom],
                        [0, 0]])
    m = trimesh.creation.revolve(profile, sections=segments)
    m.merge_vertices()
    m.update_faces(m.nondegenerate_faces())
    if m.volume < 0:
        m.invert()
    return m


def _fit(spec, hulls: list[np.ndarray], n: int, rng) -> tuple[float, float]:
    mesh = mesh_objects.mesh_in_object_frame(spec)
    lo, hi = mesh.bounds
    p = rng.uniform(lo, hi, size=(n, 3))
    inside = mesh_objects.contains(spec, p)
    in_pieces = np.zeros(n, dtype=bool)
    for h in hulls:
        try:
            in_pieces |= Delaunay(h).find_simplex(p) >= 0
        except QhullError:  # a flat piece (V-HACD makes some) holds no volume
            continue
    coverage = float((inside & in_pieces).sum() / max(1, inside.sum()))
    excess = float((in_pieces & ~inside).sum() / max(1, inside.sum()))
    return coverage, excess


def _vhacd(vertices, faces):
    import vhacdx

    parts = vhacdx.compute_vhacd(np.asarray(vertices, float), np.asarray(faces, np.uint32),
                                 maxConvexHulls=32, resolution=100_000)
    return [np.asarray(v, float) for v, _ in parts]


def decomposition(files: dict, n_points: int, vhacd: bool) -> list[dict]:
    rows = []
    rng = np.random.default_rng(0)
    for name, path in files.items():
        spec = mesh_objects.MeshObjectSpec(str(path))
        g = mesh_objects._geometry(spec)
        with tempfile.TemporaryDirectory() as cache:
            start = time.perf_counter()
            pieces = mesh_objects.convex_decomposition(g.file_vertices, g.file_faces,
                                                       directory=cache)
            cold = time.perf_counter() - start
            start = time.perf_counter()
            mesh_objects.convex_decomposition(g.file_vertices, g.file_faces, directory=cache)
            cached = time.perf_counter() - start
        start = time.perf_counter()
        hull = ConvexHull(g.file_vertices)
        floor = time.perf_counter() - start
        cov, exc = _fit(spec, [(v - g.p_FO) * spec.scale for v in pieces], n_points, rng)
        hcov, hexc = _fit(spec, [(g.file_vertices[hull.vertices] - g.p_FO) * spec.scale],
                          n_points, rng)
        row = dict(mesh=name, faces=len(g.file_faces), method="coacd", pieces=len(pieces),
                   time_s=cold, cached_s=cached, qhull_floor_s=floor, time_over_qhull=cold / floor,
                   coverage=cov, excess=exc, hull_coverage=hcov, hull_excess=hexc)
        rows.append(row)
        if vhacd:
            try:
                start = time.perf_counter()
                parts = _vhacd(g.file_vertices, g.file_faces)
                t = time.perf_counter() - start
                vcov, vexc = _fit(spec, [(v - g.p_FO) * spec.scale for v in parts], n_points,
                                  rng)
                rows.append(dict(mesh=name, faces=len(g.file_faces), method="vhacd",
                                 pieces=len(parts), time_s=t, cached_s=float("nan"),
                                 qhull_floor_s=floor, time_over_qhull=t / floor,
                                 coverage=vcov, excess=vexc, hull_coverage=hcov,
                                 hull_excess=hexc))
            except ImportError:
                print("vhacdx is not importable: V-HACD skipped")
                vhacd = False
    return rows


def trial_times(files: dict, trials: int) -> list[dict]:
    from handle_drake.trial.grasp_trial import GraspTrial, GraspTrialConfig

    rows = []
    rng = np.random.default_rng(1)
    for name, catalogue, path in (("cylinder", "cylinder", files["cylinder"]),
                                  ("cuboid", "cuboid", files["cuboid"]),
                                  ("torus", None, files["torus"])):
        configs = {"mesh": GraspTrialConfig(hand="barrett", object="mesh",
                                            object_file=str(path), space="offset")}
        if catalogue is not None:
            configs["catalogue"] = GraspTrialConfig(hand="barrett", object=catalogue,
                                                    size=ObjectSpec.default(catalogue).size,
                                                    space="offset")
        offsets = rng.uniform(-0.6, 0.6, size=(trials, 2)) * configs["mesh"].object_size
        walls, metrics, built = {}, {}, {}
        trials_by_label = {label: GraspTrial(config) for label, config in configs.items()}
        for label, trial in trials_by_label.items():
            start = time.perf_counter()
            trial.evaluate([0.0, 0.0])  # builds the diagram (and decomposes, cold cache)
            built[label] = time.perf_counter() - start
        # Interleaved, so the machine's load hits both alike.
        for x in offsets:
            for label, trial in trials_by_label.items():
                outcome = trial.evaluate(x)
                walls.setdefault(label, []).append(outcome.wall_time)
                metrics.setdefault(label, []).append(outcome.metric)
        row = dict(object=name, trials=trials,
                   mesh_trial_s=statistics.median(walls["mesh"]), mesh_build_s=built["mesh"])
        if "catalogue" in walls:
            row.update(catalogue_trial_s=statistics.median(walls["catalogue"]),
                       catalogue_build_s=built["catalogue"],
                       ratio=statistics.median(walls["mesh"]) / statistics.median(
                           walls["catalogue"]),
                       metric_max_abs_diff=float(np.max(np.abs(
                           np.array(metrics["mesh"]) - np.array(metrics["catalogue"])))))
        rows.append(row)
    return rows


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--quick", action="store_true", help="fewer points and trials")
    parser.add_argument("--vhacd", action="store_true", help="also run V-HACD (vhacdx)")
    parser.add_argument("--trials", type=int, default=None)
    add_page_arguments(parser, "mesh_objects", published={"quick": False})
    args = parser.parse_args(argv)
    run = ResultsRun("Mesh objects: convex decomposition and trial cost", args)
    n_points = 4000 if args.quick else 20000
    trials = args.trials or (3 if args.quick else 8)
    with tempfile.TemporaryDirectory() as tmp:
        os.environ[mesh_objects.CACHE_ENV] = str(Path(tmp) / "cache")
        d = Path(tmp)
        files = mesh_examples.write_examples(d)
        _cup().export(d / "cup.obj")
        files["cup"] = d / "cup.obj"
        for kind in ("cylinder", "cuboid"):
            files[kind] = mesh_objects.write_mesh(ObjectSpec.default(kind), d / f"{kind}.obj")
        deco = decomposition({k: files[k] for k in ("torus", "l_bracket", "bowl", "cup")},
                             n_points, args.vhacd)
        print(f"\n{'mesh':10s} {'method':6s} {'faces':>5s} {'pieces':>6s} {'time s':>7s} "
              f"{'cached s':>8s} {'x qhull':>8s} {'coverage':>8s} {'excess':>7s} "
              f"{'hull excess':>11s}")
        for r in deco:
            print(f"{r['mesh']:10s} {r['method']:6s} {r['faces']:5d} {r['pieces']:6d} "
                  f"{r['time_s']:7.2f} {r['cached_s']:8.4f} {r['time_over_qhull']:8.0f} "
                  f"{r['coverage']:8.3f} {r['excess']:7.3f} {r['hull_excess']:11.3f}")
        times = trial_times(files, trials)
        print(f"\n{'object':9s} {'mesh trial s':>12s} {'catalogue s':>11s} {'ratio':>6s} "
              f"{'|dBW| max':>9s}")
        for r in times:
            print(f"{r['object']:9s} {r['mesh_trial_s']:12.3f} "
                  f"{r.get('catalogue_trial_s', float('nan')):11.3f} "
                  f"{r.get('ratio', float('nan')):6.2f} "
                  f"{r.get('metric_max_abs_diff', float('nan')):9.3f}")
    out = RESULTS / "bench_mesh_objects.json"
    run.finish([{"part": "decomposition", **r} for r in deco]
               + [{"part": "trials", **r} for r in times],
               {"decomposition": deco, "trials": times, "machine_cpus": os.cpu_count()}, out)
    print(f"\nwritten {out}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
