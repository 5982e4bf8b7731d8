#!/usr/bin/env python3
"""probegi's CPU tracer against Embree on the same rays and triangles.

Runs `probegi bench` (the bare ray bench: incoherent probe rays, uniformly random
directions from the points of a probe grid over the scene) on one thread with
`--dump-rays`, then traces the dumped rays through Embree 4 (the `embreex`
Python binding, whose `run` loops over `rtcIntersect1`/`rtcOccluded1` on one
thread) and prints one JSON object: both tracers' closest-hit and any-hit rates
in Mrays/s, probegi's share of Embree's, and how often the two agree.

Needs `pip install embreex numpy` (a virtual environment is fine:
`python3 -m venv /tmp/embree && /tmp/embree/bin/pip install embreex numpy`,
then run this script with `/tmp/embree/bin/python`). The scene must have no
instances, and alpha cutouts off (`--set alpha_cutouts=false`): Embree here has
no alpha test.

Usage:
  scripts/embree-compare.py [--probegi BIN] [--repeat N] SCENE [BENCH ARGS...]
e.g.
  scripts/embree-compare.py ../shared/scenes/sibenik/sibenik.obj --probes 32,16,32 --rays-per-probe 64
"""

import argparse
import json
import os
import subprocess
import sys
import tempfile
import time

try:
    import numpy as np
    from embreex import rtcore_scene as rtcs
    from embreex.mesh_construction import TriangleMesh
except ImportError as e:
    sys.exit(f"error: {e}; install the Embree binding first: pip install embreex numpy")


def best_of(repeat, f):
    """The shortest of `repeat` timed runs of f (seconds), and f's last result."""
    best, out = float("inf"), None
    for _ in range(repeat):
        t = time.perf_counter()
        out = f()
        best = min(best, time.perf_counter() - t)
    return best, out


def main():
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--probegi", default="target/release/probegi", help="the probegi binary (build it with cargo build --release)")
    ap.add_argument("--repeat", type=int, default=3, help="timed runs per tracer; the best counts")
    ap.add_argument("scene")
    args, bench_args = ap.parse_known_args()
    if not os.path.exists(args.probegi):
        sys.exit(f"error: {args.probegi} does not exist (cargo build --release, or pass --probegi)")

    with tempfile.TemporaryDirectory() as dump:
        cmd = [args.probegi, "bench", "--scene", args.scene, "--repeat", str(args.repeat), "--dump-rays", dump, *bench_args]
        env = dict(os.environ, RAYON_NUM_THREADS="1")
        run = subprocess.run(cmd, env=env, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
        if run.returncode != 0:
            sys.exit(f"error: {' '.join(cmd)} failed:\n{run.stderr}")
        meta = json.loads(run.stdout)
        tris = np.fromfile(os.path.join(dump, "triangles.f32"), dtype="<f4").reshape(-1, 3, 3)
        rays = np.fromfile(os.path.join(dump, "rays.f32"), dtype="<f4").reshape(-1, 6)
        probegi_t = np.fromfile(os.path.join(dump, "closest_t.f32"), dtype="<f4")

    origins = np.ascontiguousarray(rays[:, :3])
    dirs = np.ascontiguousarray(rays[:, 3:])
    n = len(rays)
    any_len = np.full(n, meta["any_hit_max_distance_m"], dtype=np.float32)

    scene = rtcs.EmbreeScene()
    TriangleMesh(scene, tris)
    t = time.perf_counter()
    scene.run(origins[:1], dirs[:1])  # commits the scene: Embree builds its BVH here
    build_s = time.perf_counter() - t

    closest_s, prim = best_of(args.repeat, lambda: scene.run(origins, dirs))
    any_s, occluded = best_of(args.repeat, lambda: scene.run(origins, dirs, dists=any_len, query="OCCLUDED"))
    tfar = scene.run(origins, dirs, output=1)["tfar"]

    embree_hit = prim >= 0
    probegi_hit = np.isfinite(probegi_t)
    both = embree_hit & probegi_hit
    t_close = np.abs(tfar[both] - probegi_t[both]) <= 1e-4 * np.maximum(1.0, probegi_t[both])
    embree_closest = n / closest_s / 1e6
    embree_any = n / any_s / 1e6
    out = {
        "scene": args.scene,
        "triangles": len(tris),
        "rays": n,
        "threads": 1,
        "embree_version": "embreex (Embree 4), rtcIntersect1 / rtcOccluded1 per ray",
        # Embree builds on its own threads (all cores), probegi here on one.
        "embree_build_ms_own_threads": build_s * 1e3,
        "probegi_build_ms_one_thread": meta["bvh_build_ms"],
        "embree_closest_hit_mrays_per_s": embree_closest,
        "probegi_closest_hit_mrays_per_s": meta["closest_hit_mrays_per_s"],
        "closest_hit_probegi_over_embree": meta["closest_hit_mrays_per_s"] / embree_closest,
        "any_hit_max_distance_m": meta["any_hit_max_distance_m"],
        "embree_any_hit_mrays_per_s": embree_any,
        "probegi_any_hit_mrays_per_s": meta["any_hit_mrays_per_s"],
        "any_hit_probegi_over_embree": meta["any_hit_mrays_per_s"] / embree_any,
        "embree_closest_hit_fraction": float(embree_hit.mean()),
        "probegi_closest_hit_fraction": meta["closest_hit_fraction"],
        "embree_any_hit_fraction": float((occluded >= 0).mean()),
        "probegi_any_hit_fraction": meta["any_hit_fraction"],
        "hit_or_miss_agree": float((embree_hit == probegi_hit).mean()),
        "hit_distance_agrees_within_1e-4_rel": float(t_close.mean()) if both.any() else None,
    }
    print(json.dumps(out, indent=2))


if __name__ == "__main__":
    main()
