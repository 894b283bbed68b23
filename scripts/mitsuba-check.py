#!/usr/bin/env python3
"""Checks grotto-reference against Mitsuba 3 and writes docs/reference-mitsuba.md.

Renders each scene `grotto-reference mitsuba` wrote (SLUG.xml: the same discs, albedos, emission,
point lights and camera) with Mitsuba 3's `scalar_rgb` path tracer, in two halves with different
seeds (their difference gives Mitsuba's own per-pixel noise), and compares the result with the
reference's render of the same scene (SLUG.json: per-pixel mean and standard error).

Usage (outside CI; needs `pip install mitsuba numpy`):
    cargo run --release -p grotto-reference -- mitsuba --out target/mitsuba
    python3 scripts/mitsuba-check.py target/mitsuba --out docs/reference-mitsuba.md
"""

import argparse
import json
import os
import sys
import time

import numpy as np

try:
    import mitsuba as mi
except ImportError:
    sys.exit("mitsuba-check: Mitsuba 3 is not installed (pip install mitsuba)")


def render_halves(xml_path, spp):
    """Two independent renders of spp/2 samples each, linear RGB, rows top to bottom."""
    scene = mi.load_file(xml_path)
    half = max(1, spp // 2)
    images = []
    for seed in (1, 2):
        img = mi.render(scene, spp=half, seed=seed)
        images.append(np.array(img, dtype=np.float64)[:, :, :3])
    return images


def luminance(rgb):
    return rgb @ np.array([0.2126, 0.7152, 0.0722])


def compare(ref, ref_se, halves):
    """Mean radiance agreement and per-pixel statistics over the pixels either renderer covers."""
    mi_img = 0.5 * (halves[0] + halves[1])
    # The variance of the mean of two independent halves is (a - b)^2 / 4 per pixel (one sample of
    # it; averaged over pixels below, which is what the expected-noise figure needs).
    mi_var = (halves[0] - halves[1]) ** 2 / 4.0
    covered = (luminance(ref) > 0) | (luminance(mi_img) > 0)
    r, m = ref[covered], mi_img[covered]
    scale = float(np.mean(r))
    rel_rmse = float(np.sqrt(np.mean((m - r) ** 2)) / scale)
    noise = float(np.sqrt(np.mean(ref_se[covered] ** 2 + mi_var[covered])) / scale)
    sigma = np.sqrt(ref_se[covered] ** 2 + mi_var[covered] + 1e-30)
    within3 = float(np.mean(np.abs(m - r) <= 3.0 * sigma))
    mean_ref = r.mean(axis=0)
    mean_mi = m.mean(axis=0)
    lum_ref = float(luminance(mean_ref))
    lum_mi = float(luminance(mean_mi))
    # Standard error of the difference of the two means (pixels independent).
    n = r.shape[0]
    se_mean = float(np.sqrt(np.sum(luminance(ref_se[covered] ** 2) + luminance(mi_var[covered]))) / n / lum_ref)
    return {
        "pixels": int(covered.sum()),
        "mean_ref": mean_ref.tolist(),
        "mean_mitsuba": mean_mi.tolist(),
        "mean_diff": lum_mi / lum_ref - 1.0,
        "mean_diff_se": se_mean,
        "rel_rmse": rel_rmse,
        "noise": noise,
        "within3": within3,
        "per_channel": [float(mean_mi[k] / mean_ref[k] - 1.0) if mean_ref[k] > 0 else 0.0 for k in range(3)],
    }


def load_reference(folder, file):
    ref = json.load(open(os.path.join(folder, file)))
    w, h = ref["width"], ref["height"]
    ref["mean_img"] = np.array(ref["mean"], dtype=np.float64).reshape(h, w, 3)
    ref["se_img"] = np.array(ref["std_err"], dtype=np.float64).reshape(h, w, 3)
    return ref


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("folder", help="what `grotto-reference mitsuba` wrote")
    ap.add_argument("--out", default="docs/reference-mitsuba.md", help="the report to write")
    ap.add_argument("--spp", type=int, default=None, help="Mitsuba samples per pixel (default: the scenes')")
    ap.add_argument("--json", action="store_true", help="print the rows as JSON")
    a = ap.parse_args()
    mi.set_variant("scalar_rgb")
    index = json.load(open(os.path.join(a.folder, "index.json")))
    rows = []
    for entry in index["scenes"]:
        refs = {k: load_reference(a.folder, f) for k, f in entry["reference"].items()}
        for shape, xml_file in entry["mitsuba"].items():
            xml = os.path.join(a.folder, xml_file)
            spp = a.spp or int(open(xml).read().split('name="sample_count" value="')[1].split('"')[0])
            t0 = time.time()
            halves = render_halves(xml, spp)
            seconds = time.time() - t0
            for offset, ref in refs.items():
                row = compare(ref["mean_img"], ref["se_img"], halves)
                row.update(name=ref["name"], description=ref["description"], shape=shape, offset=offset,
                           spp_ref=ref["spp"], spp_mitsuba=spp, seconds_ref=ref["seconds"],
                           seconds_mitsuba=seconds, discs=ref["discs"], width=ref["width"], height=ref["height"])
                rows.append(row)
                print(f"{row['name']} (Mitsuba {shape}, reference offset {offset}): mean {row['mean_diff']*100:+.2f}% "
                      f"(+-{row['mean_diff_se']*100:.2f}%), rel. RMSE {row['rel_rmse']:.4f} (noise alone "
                      f"{row['noise']:.4f}), {row['within3']*100:.1f}% within 3 sigma, Mitsuba {seconds:.0f} s",
                      file=sys.stderr)
    if a.json:
        print(json.dumps(rows, indent=2))
    write_report(a.out, rows, index.get("command", "cargo run --release -p grotto-reference -- mitsuba"), a)
    print(f"wrote {a.out}", file=sys.stderr)


def lum(c):
    return 0.2126 * c[0] + 0.7152 * c[1] + 0.0722 * c[2]


def table(rows):
    lines = [
        "| scene | Mitsuba shapes | reference ray offsets | reference mean | Mitsuba mean | difference | rel. RMSE | noise alone | within 3 sigma |",
        "|---|---|---|---:|---:|---:|---:|---:|---:|",
    ]
    for r in rows:
        lines.append(
            f"| {r['name']} | {r['shape']} | {r['offset']} | {lum(r['mean_ref']):.4f} | {lum(r['mean_mitsuba']):.4f} | "
            f"{r['mean_diff']*100:+.2f}% +- {r['mean_diff_se']*100:.2f}% | {r['rel_rmse']:.4f} | {r['noise']:.4f} | "
            f"{r['within3']*100:.1f}% |"
        )
    return lines


def write_report(path, rows, command, a):
    main_rows = [r for r in rows if r["shape"] == "discs" and r["offset"] == "quarter leaf"]
    lines = [
        "# The reference checked against Mitsuba 3",
        "",
        f"Generated by `{command}` then `python3 scripts/mitsuba-check.py {a.folder} --out {a.out}` "
        f"(Mitsuba {mi.__version__}, `scalar_rgb`; do not edit by hand; `pip install mitsuba numpy` first).",
        "",
        "Every accuracy figure in [accuracy.md](accuracy.md) is an error against `grotto-reference`, "
        "grotto's own path tracer. This checks that ground truth with a renderer that shares none of "
        "its code: Mitsuba 3 renders the same scenes (written by `reference/src/mitsuba.rs`: every "
        "surfel as a Mitsuba `disk` with the same centre, normal and radius, its albedo as a two-sided "
        "diffuse BSDF, leaf emission as an area emitter on both sides, the same point lights and camera, "
        "a box pixel filter as the reference integrates each pixel's area) with its own path tracer "
        "(`path`, unbounded depth). Mitsuba renders twice with different seeds; the difference of the "
        "halves gives its own noise.",
        "",
        "Columns: mean radiance of each over the covered pixels (luminance), their difference with the "
        "standard error of that difference, relative RMSE of Mitsuba's image against the reference's "
        "(per pixel, over the mean), the RMSE that both renderers' noise alone would give, and the "
        "share of pixels whose difference is within 3 standard deviations of the two noises (one "
        "sample of each pixel's Mitsuba variance, so expect a little under 99.7% even when they agree).",
        "",
        "## The reference as the accuracy report uses it",
        "",
    ]
    lines += table(main_rows)
    lines += [
        "",
        "Per channel (Mitsuba's mean over the reference's, minus 1):",
        "",
        "| scene | red | green | blue |",
        "|---|---:|---:|---:|",
    ]
    for r in main_rows:
        c = r["per_channel"]
        lines.append(f"| {r['name']} | {c[0]*100:+.2f}% | {c[1]*100:+.2f}% | {c[2]*100:+.2f}% |")
    lines += [
        "",
        "## What the surface model changes",
        "",
        "The reference starts shadow rays a quarter leaf off the surface (as the runtime offsets its "
        "shadow lookups), because its discs are enlarged to close the gaps between samples and meet "
        "their neighbours at grazing angles on curved surfaces (`reference/src/lib.rs`, "
        "`shadow_offset_m`); bounce rays start a hair (a thousandth of a leaf) off. Rows with shadow "
        "offset *hair* are the reference with shadow rays a hair off too; rows *quarter leaf, bounces "
        "too* are the reference as it was before this check, with bounce rays a quarter leaf off as "
        "well. The "
        "hand-built scenes' surfels are their voxel faces (one per open face), so Mitsuba also renders "
        "those faces as squares (*faces*): the exact surface the discs stand for.",
        "",
    ]
    lines += table(rows)
    lines += ["", "Scenes:", ""]
    for r in main_rows:
        lines.append(
            f"- **{r['name']}**: {r['description']}; {r['discs']} discs, {r['width']}x{r['height']} pixels "
            f"({r['pixels']} covered); reference {r['spp_ref']} paths per pixel in {r['seconds_ref']:.0f} s, "
            f"Mitsuba {r['spp_mitsuba']} in {r['seconds_mitsuba']:.0f} s (2 cores)."
        )
    lines.append("")
    tmp = path + ".tmp"
    with open(tmp, "w") as f:
        f.write("\n".join(lines))
    os.replace(tmp, path)


if __name__ == "__main__":
    main()
