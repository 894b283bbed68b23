#!/usr/bin/env python3
"""CloudCompare's command-line normals on the same cloud grotto's bench-normals measures.

    grotto-pack bench-normals --dir /tmp/bn --points 1000000 --k 16 --threads 2 --export /tmp/bn/cloud.ply
    python3 bench/cloudcompare_normals.py /tmp/bn/cloud.ply --k 16

CloudCompare (Debian's `cloudcompare` 2.11, run headless with QT_QPA_PLATFORM=offscreen) estimates
normals by local least-squares planes over an octree radius search (`-OCTREE_NORMALS R -MODEL LS`).
It searches a radius, not k neighbours: R is the median distance to the k-th neighbour over 20,000
sampled points (Open3D's kd-tree), so the neighbourhoods hold k points on median, like grotto's and
Open3D's. The time is the one CloudCompare prints for the normals alone ("[ComputeCloudNormals]
Timing"), best of `--repeat` runs; CloudCompare uses every core (it has no thread option).
Accuracy is the angle to the true normal ignoring orientation, as for Open3D.
"""
import argparse
import json
import os
import re
import subprocess
import tempfile

import numpy as np
import open3d as o3d

PLY_TYPES = {"double": "f8", "float": "f4", "uchar": "u1", "int": "i4", "uint": "u4", "short": "i2",
             "ushort": "u2", "char": "i1", "float32": "f4", "float64": "f8", "uint8": "u1", "int32": "i4"}


def read_ply(path):
    """The vertex properties of a binary little-endian PLY, by name."""
    with open(path, "rb") as f:
        names, count = [], 0
        in_vertex = False
        while True:
            line = f.readline().decode("ascii").strip()
            if line.startswith("format") and "binary_little_endian" not in line:
                raise SystemExit(f"{path}: only binary little-endian PLY is read here ({line})")
            if line.startswith("element"):
                _, name, n = line.split()
                in_vertex = name == "vertex"
                if in_vertex:
                    count = int(n)
            elif line.startswith("property") and in_vertex:
                _, kind, name = line.split()
                names.append((name, "<" + PLY_TYPES[kind]))
            elif line == "end_header":
                break
        return np.fromfile(f, dtype=np.dtype(names), count=count)


def main():
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("cloud")
    ap.add_argument("--k", type=int, default=16)
    ap.add_argument("--repeat", type=int, default=3)
    args = ap.parse_args()

    truth_ply = read_ply(args.cloud)
    xyz = np.stack([truth_ply["x"], truth_ply["y"], truth_ply["z"]], axis=1)
    truth = np.stack([truth_ply["nx"], truth_ply["ny"], truth_ply["nz"]], axis=1).astype(np.float64)
    n = len(xyz)
    tree = o3d.geometry.KDTreeFlann(o3d.geometry.PointCloud(o3d.utility.Vector3dVector(xyz)))
    rng = np.random.default_rng(1)
    kth = [np.sqrt(tree.search_knn_vector_3d(xyz[i], args.k)[2][-1]) for i in rng.choice(n, 20000)]
    radius = float(np.median(kth))

    env = dict(os.environ, QT_QPA_PLATFORM="offscreen")
    best, est = float("inf"), None
    with tempfile.TemporaryDirectory() as tmp:
        out = os.path.join(tmp, "cc.ply")
        for _ in range(args.repeat):
            run = subprocess.run(
                ["CloudCompare", "-SILENT", "-AUTO_SAVE", "OFF", "-O", args.cloud, "-OCTREE_NORMALS", f"{radius}",
                 "-MODEL", "LS", "-C_EXPORT_FMT", "PLY", "-PLY_EXPORT_FMT", "BINARY_LE", "-SAVE_CLOUDS", "FILE", out],
                env=env, capture_output=True, text=True, check=True)
            timing = re.search(r"\[ComputeCloudNormals\] Timing: ([0-9.]+) s", run.stdout + run.stderr)
            if timing is None:
                raise SystemExit("CloudCompare printed no normals timing:\n" + run.stdout[-2000:])
            best = min(best, float(timing.group(1)))
        cc = read_ply(out)
        est = np.stack([cc["nx"], cc["ny"], cc["nz"]], axis=1).astype(np.float64)
        if len(est) != n:
            raise SystemExit(f"CloudCompare wrote {len(est)} points of {n}")
        moved = np.abs(np.stack([cc["x"], cc["y"], cc["z"]], axis=1) - xyz).max()
        if moved > 1e-3:
            raise SystemExit(f"CloudCompare reordered or moved the points (up to {moved} m)")
    lens = np.linalg.norm(est, axis=1)
    valid = lens > 0.5
    cos = np.clip(np.abs(np.sum(est[valid] / lens[valid, None] * truth[valid], axis=1)), 0.0, 1.0)
    err = np.degrees(np.arccos(cos))
    version = subprocess.run(["dpkg-query", "-W", "-f=${Version}", "cloudcompare"], capture_output=True, text=True)
    print(json.dumps({
        "tool": f"CloudCompare {version.stdout.strip() or '?'} (-OCTREE_NORMALS, -MODEL LS)",
        "points": n,
        "k": args.k,
        "radius_m": radius,
        "seconds": best,
        "normals_per_second": n / best,
        "without_normal": int(n - valid.sum()),
        "mean_deg": float(err.mean()),
        "p95_deg": float(np.percentile(err, 95)),
    }, indent=2))


if __name__ == "__main__":
    main()
