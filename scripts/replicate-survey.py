#!/usr/bin/env python3
"""Writes a manifest that places a survey's scans N times side by side, for build benchmarks.

    scripts/replicate-survey.py SRC/manifest.toml OUT/manifest.toml COPIES SHIFT_M

Copy r of every scan is moved r * SHIFT_M metres east (+x); paths point at the original files, so
a 10^9-point build input takes the disk space of the 10^8 one (docs/benchmarks.md). Handles the
manifests `grotto-pack synth` writes: LAS, LAZ and PLY scans with a translation and rotation, and
E57 scans without, whose pose is read from the file's XML section (E57 pages end in a 4-byte CRC).
"""
import os
import re
import struct
import sys


def e57_pose(path):
    """Rotation (w, x, y, z) and translation of the first scan's pose in an E57 file."""
    with open(path, "rb") as f:
        head = f.read(48)
        if head[:8] != b"ASTM-E57":
            sys.exit(f"{path}: not an E57 file")
        _, _, _, xml_offset, xml_length, page = struct.unpack("<IIQQQQ", head[8:48])
        start = xml_offset - xml_offset % page
        f.seek(start)
        raw = f.read((xml_offset % page + xml_length) // (page - 4) * page + 2 * page)
    logical = b"".join(raw[i : i + page - 4] for i in range(0, len(raw), page))
    skip = xml_offset % page
    xml = logical[skip : skip + xml_length].decode()

    def floats(tag, keys):
        body = xml.split("<" + tag, 1)[1]
        return [float(re.search(r'<%s type="Float">([^<]+)<' % k, body).group(1)) for k in keys]

    return floats("rotation", "wxyz"), floats("translation", "xyz")


def main():
    if len(sys.argv) != 5:
        sys.exit(__doc__)
    src, out, copies, shift = sys.argv[1], sys.argv[2], int(sys.argv[3]), float(sys.argv[4])
    src_dir = os.path.dirname(os.path.abspath(src))
    out_dir = os.path.dirname(os.path.abspath(out))
    blocks = open(src).read().split("[[scan]]")[1:]
    lines = [f"# {copies} copies of {src}, copy r moved r * {shift} m east (scripts/replicate-survey.py).\n"]
    for r in range(copies):
        for block in blocks:
            path = re.search(r'path = "([^"]+)"', block).group(1)
            if "translation" in block:
                t = [float(v) for v in re.search(r"translation = \[([^\]]+)\]", block).group(1).split(",")]
                q = re.search(r"rotation = \[([^\]]+)\]", block).group(1)
            else:
                rot, t = e57_pose(os.path.join(src_dir, path))
                q = ", ".join(repr(v) for v in rot)
            t[0] += shift * r
            rel = os.path.relpath(os.path.join(src_dir, path), out_dir)
            lines.append(
                f'[[scan]]\npath = "{rel}"\ntranslation = [{t[0]:.4f}, {t[1]:.4f}, {t[2]:.4f}]\n'
                f"rotation = [{q}]\norigin = [0.0, 0.0, 0.0]\n\n"
            )
    os.makedirs(out_dir, exist_ok=True)
    open(out, "w").write("".join(lines))
    print(f"wrote {out}: {len(lines) - 1} scans")


main()
