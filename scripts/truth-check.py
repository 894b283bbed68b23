#!/usr/bin/env python3
"""The true-surface benchmark: grotto's picture of the scanned points against the cave.

`grotto-reference truth` meshes the synthetic cave's exact surface and writes a Mitsuba 3 scene
of it per camera and transport (DIR/CAMERA-direct.xml, DIR/CAMERA-full.xml, DIR/cameras.json).
This renders them with Mitsuba (`scalar_rgb`, two halves with different seeds: their difference
gives Mitsuba's own noise), renders the same cameras with `grotto render` from the package built
from the scans, with the front-most disc (`--no-splat-blend`) and with
blended splats (the default), and compares each with Mitsuba over every pixel (silhouettes and
holes included): FLIP (NVIDIA's flip-evaluator, LDR, both tonemapped as grotto shows them: ACES
and sRGB at the truth's auto exposure) and relative RMSE of linear radiance. Writes the report
(docs/accuracy-truth.md), its rows (JSON) and side-by-side images (truth, before, after, FLIP of
after).

Usage (outside CI; needs `pip install mitsuba numpy flip-evaluator pillow`):
    target/release/grotto-pack demo --out out
    target/release/grotto-reference truth --out target/truth
    python3 scripts/truth-check.py target/truth
"""

import argparse
import glob
import hashlib
import json
import os
import subprocess
import sys
import time

import numpy as np

# Dr.Jit's LLVM backend (Mitsuba's vectorised variants) needs libLLVM 15 or newer; Debian 12
# has it beside Mesa. The direct light renders there, ten times faster than `scalar_rgb`.
for _lib in sorted(glob.glob("/usr/lib/*/libLLVM-1[5-9]*.so*")):
    os.environ.setdefault("DRJIT_LIBLLVM_PATH", _lib)
try:
    import mitsuba as mi
    import flip_evaluator as flip
    from PIL import Image
except ImportError as e:
    sys.exit(f"truth-check: {e} (pip install mitsuba numpy flip-evaluator pillow)")

MODES = [
    ("before", "front-most disc (--no-splat-blend)", ["--no-splat-blend"]),
    ("after", "blended splats", []),
    ("after_aa", "blended splats, 8 samples a pixel (the viewers' anti-aliasing at rest)", ["--samples", "8"]),
]
TRANSPORTS = [
    # No bounce: the lights with shadow maps per pixel, those beyond the budget from the leaves.
    ("direct", "direct light alone", ["--bounces", "0"]),
    ("full", "full transport", []),
]


def luminance(rgb):
    return rgb @ np.array([0.2126, 0.7152, 0.0722])


def auto_exposure(hdr):
    """grotto's auto exposure (runtime/src/render/params.rs): mean log luminance to 0.18."""
    lum = luminance(hdr)
    lum = lum[np.isfinite(lum) & (lum > 0)]
    if lum.size == 0:
        return 1.0
    return float(np.clip(0.18 / np.exp(np.log(np.maximum(lum, 1e-6)).mean()), 1e-6, 1e9))


def aces_srgb(hdr, exposure):
    """grotto's tonemap (shaders/color.wgsl): ACES fit, then sRGB; values in [0, 1]."""
    x = np.maximum(hdr * exposure, 0.0)
    m = np.clip((x * (2.51 * x + 0.03)) / (x * (2.43 * x + 0.59) + 0.14), 0.0, 1.0)
    return np.where(m <= 0.0031308, 12.92 * m, 1.055 * np.power(m, 1 / 2.4) - 0.055)


def rel_rmse(got, truth):
    """Relative RMSE over every pixel and channel, and the ratio of means minus 1."""
    return (
        float(np.sqrt(((got - truth) ** 2).sum() / max((truth**2).sum(), 1e-30))),
        float(got.sum() / max(truth.sum(), 1e-30) - 1.0),
    )


def flip_ldr(got, truth, exposure):
    """Mean LDR FLIP and its magma map, both images tonemapped as grotto shows them."""
    ref = aces_srgb(truth, exposure).astype(np.float32)
    test = aces_srgb(got, exposure).astype(np.float32)
    err, mean, _ = flip.evaluate(ref, test, "LDR")
    return float(mean), np.asarray(err)


def mitsuba_halves(xml_path, spp, variant):
    """Mitsuba's two halves, cached beside the scene: keyed by the XML's (and its mesh's) hash, the
    samples and the variant, so judging a new grotto does not re-run the path tracer."""
    h = hashlib.sha256(open(xml_path, "rb").read())
    mesh = os.path.join(os.path.dirname(xml_path), "mesh.ply")
    if os.path.exists(mesh):
        st = os.stat(mesh)
        h.update(f"{st.st_size}:{st.st_mtime_ns}".encode())
    h.update(f"{spp}:{variant}:{mi.__version__}".encode())
    cache = f"{os.path.splitext(xml_path)[0]}-truth-{h.hexdigest()[:16]}.npz"
    if os.path.exists(cache):
        z = np.load(cache)
        return [z["h1"], z["h2"]], True
    mi.set_variant(variant)
    scene = mi.load_file(xml_path)
    half = max(1, spp // 2)
    out = []
    for seed in (1, 2):
        out.append(np.array(mi.render(scene, spp=half, seed=seed), dtype=np.float64)[:, :, :3])
    np.savez(cache + ".tmp.npz", h1=out[0], h2=out[1])
    os.replace(cache + ".tmp.npz", cache)
    return out, False


def llvm_ok():
    return "llvm_ad_rgb" in mi.variants() and "DRJIT_LIBLLVM_PATH" in os.environ


def read_exr(path):
    return np.array(mi.Bitmap(path), dtype=np.float64)[:, :, :3]


def grotto_render(grotto, package, cam, size, extra, out_path):
    args = [
        grotto, "render", package,
        "--eye", ",".join(f"{v:.6f}" for v in cam["eye_world_m"]),
        "--look-at", ",".join(f"{v:.6f}" for v in cam["look_at_world_m"]),
        "--up", ",".join(f"{v:.6f}" for v in cam["up"]),
        "--fov", f"{cam['fov_y_deg']:.6f}",
        "--size", size, "--exposure", "1", "--out", out_path,
    ] + extra
    t = time.time()
    subprocess.run(args, check=True, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
    return time.time() - t


def save_strip(rgb01, path):
    """JPEG (quality 90): the truth's noise makes a PNG of four 640x480 panels 1.5 MB."""
    Image.fromarray((np.clip(rgb01, 0, 1) * 255 + 0.5).astype(np.uint8)).save(path, quality=90)


def main():
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("dir", help="what grotto-reference truth wrote")
    ap.add_argument("--grotto", default="target/release/grotto")
    ap.add_argument("--out", default="docs/accuracy-truth.md")
    ap.add_argument("--images", default="docs/images/truth")
    ap.add_argument("--report-only", action="store_true",
                    help="rewrite the report from its JSON rows (no rendering)")
    ap.add_argument("--transport", choices=[t[0] for t in TRANSPORTS],
                    help="judge one transport only (a quick check: give --out and --images elsewhere)")
    args = ap.parse_args()
    if args.report_only:
        saved = json.load(open(os.path.splitext(args.out)[0] + ".json"))
        write_report(args, saved["meta"], saved["rows"])
        return
    mi.set_variant("scalar_rgb")
    meta = json.load(open(os.path.join(args.dir, "cameras.json")))
    meta["runtime_commit"] = subprocess.run(
        ["git", "rev-parse", "--short", "HEAD"], capture_output=True, text=True).stdout.strip()
    size = f"{meta['width']}x{meta['height']}"
    os.makedirs(args.images, exist_ok=True)
    rows = []
    previous = {}
    try:
        for r in json.load(open(os.path.splitext(args.out)[0] + ".json"))["rows"]:
            previous[(r["camera"], r["transport"])] = r["mitsuba_s"]
    except (OSError, ValueError, KeyError):
        pass
    for cam in meta["cameras"]:
        for tslug, tname, textra in TRANSPORTS:
            if args.transport and tslug != args.transport:
                continue
            xml = os.path.join(args.dir, f"{cam['slug']}-{tslug}.xml")
            spp = meta["spp_direct"] if tslug == "direct" else meta["spp_full"]
            t = time.time()
            # The full transport renders in `scalar_rgb`: Dr.Jit 1.x's LLVM backend fails to compile
            # Mitsuba's path tracer with LLVM 15 here ("Cannot select", measured); the direct
            # integrator compiles.
            variant = "llvm_ad_rgb" if tslug == "direct" and llvm_ok() else "scalar_rgb"
            (h1, h2), cached = mitsuba_halves(xml, spp, variant)
            mitsuba_s = time.time() - t
            if cached:
                # The time of the render that made the cache, from the last report.
                mitsuba_s = previous.get((cam["name"], tslug), mitsuba_s)
            truth = 0.5 * (h1 + h2)
            exposure = auto_exposure(truth)
            # The truth's own noise: each half against the other, scaled to the mean of both.
            noise_rmse = rel_rmse(h1, h2)[0] / 2.0
            noise_flip = flip_ldr(h1, h2, exposure)[0]
            shown = [aces_srgb(truth, exposure)]
            for mslug, mname, mextra in MODES:
                exr = os.path.join(args.dir, f"{cam['slug']}-{tslug}-{mslug}.exr")
                grotto_s = grotto_render(args.grotto, meta["package"], cam, size, textra + mextra, exr)
                got = read_exr(exr)
                rmse, bias = rel_rmse(got, truth)
                f, fmap = flip_ldr(got, truth, exposure)
                rows.append({
                    "camera": cam["name"], "transport": tslug, "mode": mslug, "flip": f,
                    "rel_rmse": rmse, "bias": bias, "noise_rel_rmse": noise_rmse,
                    "noise_flip": noise_flip, "mitsuba_spp": spp, "mitsuba_s": mitsuba_s,
                    "grotto_s": grotto_s, "exposure": exposure, "mitsuba_variant": variant,
                })
                print(f"{cam['name']:>14} {tslug:>6} {mslug:>6}: FLIP {f:.4f} rel RMSE {rmse:.4f} "
                      f"bias {bias:+.3f} (truth noise: FLIP {noise_flip:.4f}, RMSE {noise_rmse:.4f})",
                      flush=True)
                if mslug != "after_aa":
                    shown.append(aces_srgb(got, exposure))
                if mslug == "after":
                    shown.append(fmap)
            strip = np.concatenate(shown, axis=1)
            save_strip(strip, os.path.join(args.images, f"{cam['slug']}-{tslug}.jpg"))
    write_report(args, meta, rows)


def write_report(args, meta, rows):
    base = os.path.splitext(args.out)[0]
    json.dump({"meta": meta, "rows": rows}, open(base + ".json", "w"), indent=1)
    rel_images = os.path.relpath(args.images, os.path.dirname(args.out) or ".")
    by = {(r["camera"], r["transport"], r["mode"]): r for r in rows}
    lines = [
        "# The picture against the cave: grotto against the true surface",
        "",
        "Generated by `target/release/grotto-reference truth --out target/truth` then "
        "`python3 scripts/truth-check.py target/truth` (Mitsuba 3.9.1: `llvm_ad_rgb` for the direct light, `scalar_rgb` for full transport; flip-evaluator; "
        "do not edit by hand). The package is the README's demo cave (`grotto-pack demo`); grotto as of "
        f"commit {meta.get('runtime_commit', '?')}.",
        "",
        "Every figure in [accuracy.md](accuracy.md) compares grotto with a path tracer run on the same "
        "discs, so it says how right the light is on grotto's model of the surface. This says how close "
        "grotto's picture is to the cave itself. The synthetic cave is an implicit function, so its true "
        f"surface is known: meshed by surface nets on a {meta['cell_m'] * 100:.0f} cm grid "
        f"({meta['triangles']:,} triangles; the mesh's error is about a millimetre on the cave's "
        "roughest bumps, a leaf is 25 cm) with the cave's own colours as albedo, lit by the package's "
        f"{meta['lights']} point lights, rendered by Mitsuba 3 with the same cameras at "
        f"{meta['width']}x{meta['height']}. grotto renders the package built from the cave's "
        "simulated scans (noisy points, estimated normals, holes where no scanner saw).",
        "",
        "Both judged over every pixel, silhouettes and holes included: FLIP (LDR, both images "
        "tonemapped as grotto shows them, at the truth's auto exposure; 0 is identical) and relative "
        "RMSE of linear radiance (with the ratio of the mean radiance, minus 1, as bias). *Truth noise* "
        "is Mitsuba's own: its two halves against each other, so errors near it are noise, not grotto. "
        "*Before* is the front-most disc alone (`--no-splat-blend`), *after* blended splats (the "
        "default), *AA* blended splats with `--samples 8`, the viewers' anti-aliasing at rest (its cost: docs/runtime.md, "
        "\"Anti-aliasing\"). *Direct* is direct light alone (grotto `--bounces 0`: lights with shadow maps per pixel, those beyond the budget per leaf, Mitsuba's "
        "`direct`); *full* is every bounce (grotto's default preset, Mitsuba's `path`).",
        "",
        "| camera | light | FLIP before | FLIP after | change | FLIP after, AA | rel. RMSE before | rel. RMSE after | rel. RMSE after, AA | bias after | truth noise (FLIP / RMSE) |",
        "|---|---|---:|---:|---:|---:|---:|---:|---:|---:|---:|",
    ]
    for cam in meta["cameras"]:
        for tslug, tname, _ in TRANSPORTS:
            if (cam["name"], tslug, "after") not in by:
                continue
            b, a, aa = (by[(cam["name"], tslug, m)] for m in ("before", "after", "after_aa"))
            lines.append(
                f"| {cam['name']} | {tname} | {b['flip']:.4f} | {a['flip']:.4f} | "
                f"{(a['flip'] / b['flip'] - 1) * 100:+.0f}% | {aa['flip']:.4f} | {b['rel_rmse']:.4f} | "
                f"{a['rel_rmse']:.4f} | {aa['rel_rmse']:.4f} | {a['bias']:+.3f} | "
                f"{a['noise_flip']:.4f} / {a['noise_rel_rmse']:.4f} |"
            )
    lines += ["", "Each image: the truth (Mitsuba), before, after, and the FLIP map of after "
              "(magma: black agrees, bright differs).", ""]
    for cam in meta["cameras"]:
        for tslug, tname, _ in TRANSPORTS:
            if (cam["name"], tslug, "after") not in by:
                continue
            lines.append(f"**{cam['name']}, {tname}**")
            lines.append("")
            lines.append(f"![{cam['name']} {tname}]({rel_images}/{cam['slug']}-{tslug}.jpg)")
            lines.append("")
    spp = (meta["spp_direct"], meta["spp_full"])
    lines.append(f"Mitsuba: {spp[0]} samples a pixel for the direct light, {spp[1]} for full transport "
                 "(two halves); run times per image: " + ", ".join(
                     f"{r['camera']} {r['transport']} {r['mitsuba_s']:.0f} s" for r in rows if r["mode"] == "after") + ".")
    open(args.out, "w").write("\n".join(lines) + "\n")
    print(f"wrote {args.out}")


if __name__ == "__main__":
    main()
