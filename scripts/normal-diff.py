#!/usr/bin/env python3
"""Angle between two normal (or tangent) maps of `symframe estimate`, pixel by pixel.

Usage: scripts/normal-diff.py A/normals.npy B/normals.npy [--axis]

Reads two float32 .npy maps of shape (H, W, 3) (standard library only, no numpy), and prints
the angle differences in degrees over the pixels where both are finite: median (p50), p99 and
max, and how many pixels have a value in one map only. `--axis` treats v and -v as equal
(tangents). docs/performance.md uses it to measure the half-float cache against float32.
"""
import ast
import math
import struct
import sys


def read_npy(path):
    with open(path, "rb") as f:
        data = f.read()
    if data[:6] != b"\x93NUMPY":
        sys.exit(f"{path}: not an .npy file")
    major = data[6]
    if major == 1:
        hlen = struct.unpack("<H", data[8:10])[0]
        start = 10
    else:
        hlen = struct.unpack("<I", data[8:12])[0]
        start = 12
    header = ast.literal_eval(data[start:start + hlen].decode("latin1"))
    if header["descr"] not in ("<f4", "=f4") or header["fortran_order"]:
        sys.exit(f"{path}: expected little-endian float32 in C order, got {header}")
    shape = header["shape"]
    n = 1
    for s in shape:
        n *= s
    body = data[start + hlen:]
    return shape, struct.unpack(f"<{n}f", body[:4 * n])


def quantile(v, q):
    if not v:
        return float("nan")
    return v[min(len(v) - 1, int(q * (len(v) - 1) + 0.5))]


def main():
    args = [a for a in sys.argv[1:] if not a.startswith("--")]
    axis = "--axis" in sys.argv
    if len(args) != 2:
        sys.exit(__doc__)
    (sa, a), (sb, b) = read_npy(args[0]), read_npy(args[1])
    if sa != sb or sa[-1] != 3:
        sys.exit(f"shapes differ or are not (H, W, 3): {sa} {sb}")
    angles, only_one = [], 0
    for i in range(0, len(a), 3):
        u, v = a[i:i + 3], b[i:i + 3]
        fu, fv = all(map(math.isfinite, u)), all(map(math.isfinite, v))
        if fu != fv:
            only_one += 1
        if not (fu and fv):
            continue
        nu = math.sqrt(sum(x * x for x in u))
        nv = math.sqrt(sum(x * x for x in v))
        if nu == 0 or nv == 0:
            continue
        c = sum(x * y for x, y in zip(u, v)) / (nu * nv)
        if axis:
            c = abs(c)
        angles.append(math.degrees(math.acos(max(-1.0, min(1.0, c)))))
    angles.sort()
    print(
        f"{len(angles)} pixels: p50 {quantile(angles, 0.5):.5f} deg, p99 {quantile(angles, 0.99):.5f} deg, "
        f"max {angles[-1] if angles else float('nan'):.5f} deg, identical {sum(1 for x in angles if x == 0.0)}; "
        f"{only_one} pixels with a value in one map only"
    )


if __name__ == "__main__":
    main()
