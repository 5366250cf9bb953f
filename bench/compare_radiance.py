#!/usr/bin/env python3
"""Compares the radiance files of two builds written by `bench_probes --part image` on the same arguments.

Each frame in a file is the radiance with probes, then without (float32 RGB, width x height x 3 each). Both
builds render the same frames with everything but the probes' shading deterministic and the same, so
new - old (with probes) is the change in the indirect term times the albedo. Printed: the largest and the RMS
difference over all pixels, channels and frames, the mean radiance with probes (the scale to read them
against), the mean |with - without| (what the probes change: their term minus the sky term they replace), and
the 99.9th percentile of |new - old| / old per value (values above 1e-6).

Usage: compare_radiance.py OLD NEW WIDTH HEIGHT
"""
import array
import math
import sys


def frames(path, n):
    data = array.array("f")
    with open(path, "rb") as f:
        data.frombytes(f.read())
    if sys.byteorder != "little":
        data.byteswap()
    if len(data) % (2 * n):
        sys.exit(f"{path}: {len(data)} floats is not a whole number of frames of {n}")
    for first in range(0, len(data), 2 * n):
        yield data[first:first + n], data[first + n:first + 2 * n]


def main():
    if len(sys.argv) != 5:
        sys.exit(__doc__)
    old_path, new_path, width, height = sys.argv[1], sys.argv[2], int(sys.argv[3]), int(sys.argv[4])
    n = width * height * 3
    worst = sq = contribution = radiance = 0.0
    relative = []
    count = 0
    for (old, old_without), (new, _) in zip(frames(old_path, n), frames(new_path, n)):
        for i in range(n):
            d = abs(new[i] - old[i])
            worst = max(worst, d)
            sq += d * d
            contribution += abs(old[i] - old_without[i])
            radiance += old[i]
            if old[i] > 1e-6:
                relative.append(d / old[i])
        count += n
    relative.sort()
    p999 = relative[min(len(relative) - 1, int(0.999 * len(relative)))] if relative else 0.0
    print(f"values {count}: max |new - old| {worst:.3g}, RMS {math.sqrt(sq / count):.3g}; mean radiance "
          f"{radiance / count:.3g}, mean |with - without| {contribution / count:.3g}; 99.9th percentile of "
          f"|new - old| / old {p999:.3g}")


if __name__ == "__main__":
    main()
