#!/usr/bin/env python3
"""Open3D's estimate_normals on the same cloud grotto's bench-normals measures, for docs/benchmarks.md.

    grotto-pack bench-normals --dir /tmp/bn --points 1000000 --k 16 --threads 2 --export /tmp/bn/cloud.ply
    OMP_NUM_THREADS=2 python3 bench/open3d_normals.py /tmp/bn/cloud.ply --k 16

The PLY holds the points (cave frame, metres) and their true normals from the analytic surface.
Open3D estimates normals with a KNN-16 search (CPU); accuracy is the angle to the truth, ignoring
orientation (Open3D's orientation is a separate step that needs one viewpoint; grotto orients each
point toward its own scanner), timed over `--repeat` runs, best taken.
"""
import argparse
import json
import time

import numpy as np
import open3d as o3d


def main():
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("cloud")
    ap.add_argument("--k", type=int, default=16)
    ap.add_argument("--repeat", type=int, default=3)
    args = ap.parse_args()

    pcd = o3d.io.read_point_cloud(args.cloud)
    truth = np.asarray(pcd.normals).copy()
    n = len(pcd.points)
    best = float("inf")
    for _ in range(args.repeat):
        work = o3d.geometry.PointCloud(pcd.points)
        start = time.perf_counter()
        work.estimate_normals(search_param=o3d.geometry.KDTreeSearchParamKNN(knn=args.k))
        best = min(best, time.perf_counter() - start)
    est = np.asarray(work.normals)
    cos = np.clip(np.abs(np.sum(est * truth, axis=1)), 0.0, 1.0)
    err = np.degrees(np.arccos(cos))
    print(json.dumps({
        "tool": f"open3d {o3d.__version__}",
        "points": n,
        "k": args.k,
        "seconds": best,
        "normals_per_second": n / best,
        "mean_deg": float(err.mean()),
        "p95_deg": float(np.percentile(err, 95)),
    }, indent=2))


if __name__ == "__main__":
    main()
