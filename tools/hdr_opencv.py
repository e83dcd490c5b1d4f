"""OpenCV's HDR functions on an exposure stack, timed, for comparison with `lumen hdr`.

Usage (the peers' virtual environment, ../shared/tools/peers-venv.sh):
    $PEERS_PY tools/hdr_opencv.py ../shared/data/hdr/memorial/exposure_times_seconds.txt [out.exr]

Prints the best of five runs of CalibrateDebevec (70 samples, λ 10, OpenCV's defaults),
CalibrateRobertson and MergeDebevec, the response's NaN count and monotonicity per channel,
and the merge's range in stops; with out.exr also writes the merged radiance.
"""
import os
import sys
import time

import cv2
import numpy as np


def best(f, n=5):
    times, out = [], None
    for _ in range(n):
        t = time.perf_counter()
        out = f()
        times.append(time.perf_counter() - t)
    return min(times), out


def main(listing, out=None):
    folder = os.path.dirname(listing)
    names, times = [], []
    for line in open(listing):
        if line.strip() and not line.startswith("#"):
            n, t = line.split()
            names.append(os.path.join(folder, n))
            times.append(float(t))
    images = [cv2.imread(n) for n in names]
    t = np.array(times, dtype=np.float32)
    cv2.setNumThreads(2)
    td, deb = best(lambda: cv2.createCalibrateDebevec().process(images, t))
    tr, rob = best(lambda: cv2.createCalibrateRobertson().process(images, t))
    tm, hdr = best(lambda: cv2.createMergeDebevec().process(images, t, deb))
    for name, r in (("Debevec", deb), ("Robertson", rob)):
        r = r.reshape(256, 3)
        nan = int(np.isnan(r).sum())
        mono = [bool(np.all(np.diff(r[:, c]) > 0)) for c in range(3)]
        print(f"{name}: {nan} NaN values; strictly increasing per channel (B, G, R): {mono}")
    lum = hdr[..., 2] * 0.2126 + hdr[..., 1] * 0.7152 + hdr[..., 0] * 0.0722
    lum = lum[lum > 0]
    print(f"CalibrateDebevec {td*1e3:.1f} ms, CalibrateRobertson {tr*1e3:.1f} ms, MergeDebevec {tm*1e3:.1f} ms "
          f"({len(images) * images[0].shape[0] * images[0].shape[1] / 1e6 / tm:.0f} Mpixel-frames/s); "
          f"merged range {np.log2(lum.max() / lum.min()):.1f} stops")
    if out:
        cv2.imwrite(out, hdr)


if __name__ == "__main__":
    main(*sys.argv[1:])
