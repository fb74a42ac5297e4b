#!/usr/bin/env python3
# SPDX-License-Identifier: Apache-2.0
"""Writes a closed torus cage of N x M quads as an OBJ: a large cage for measuring scene build
time and memory (issue 18, item 6: `scripts/make_torus.py 1000 1000 out/torus1m.obj` makes the
1,000,000-quad cage), or, with --inward, the same torus wound inward (faces oriented towards
the inside).

    scripts/make_torus.py N M OUT.obj [--inward] [--major R] [--minor r]
"""
import argparse
import math
import os
import sys


def main():
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("n", type=int, help="quads around the ring (major circle), >= 3")
    p.add_argument("m", type=int, help="quads around the tube (minor circle), >= 3")
    p.add_argument("out", help="OBJ file to write (written to a temporary, then renamed)")
    p.add_argument("--inward", action="store_true", help="wind every face inward")
    p.add_argument("--major", type=float, default=1.0, help="ring radius (default 1)")
    p.add_argument("--minor", type=float, default=0.35, help="tube radius (default 0.35)")
    a = p.parse_args()
    if a.n < 3 or a.m < 3:
        sys.exit("make_torus.py: error: N and M must be at least 3")

    lines = []
    for i in range(a.n):
        phi = 2.0 * math.pi * i / a.n
        cp, sp = math.cos(phi), math.sin(phi)
        for j in range(a.m):
            theta = 2.0 * math.pi * j / a.m
            r = a.major + a.minor * math.cos(theta)
            lines.append("v %.7g %.7g %.7g\n" % (r * cp, a.minor * math.sin(theta), r * sp))
    for i in range(a.n):
        i1 = (i + 1) % a.n
        for j in range(a.m):
            j1 = (j + 1) % a.m
            # Counter-clockwise seen from outside: along the tube first, then along the ring.
            q = (i * a.m + j + 1, i * a.m + j1 + 1, i1 * a.m + j1 + 1, i1 * a.m + j + 1)
            if a.inward:
                q = q[::-1]
            lines.append("f %d %d %d %d\n" % q)
    tmp = a.out + ".tmp"
    with open(tmp, "w") as f:
        f.writelines(lines)
    os.replace(tmp, a.out)


if __name__ == "__main__":
    main()
