"""OpenCV's HDR functions on an exposure stack, timed, for comparison with `lumen hdr`.

Usage (the peers' virtual environment, ../shared/tools/peers-venv.sh):
    $PEERS_PY tools/hdr_opencv.py ../shared/data/hdr/memorial/exposure_times_seconds.txt [out.hdr]

Prints the best of five runs of CalibrateDebevec (70 samples, λ 10, OpenCV's defaults),
CalibrateRobertson, MergeDebevec and MergeMertens, the response's NaN count and monotonicity
per channel, and the merge's range in stops; with out.hdr (Radiance RGBE; .exr where the
OpenCV build writes EXR, which PyPI's does not) also writes the merged radiance,
and fusion.png (MergeMertens, clipped to 0..1, 8-bit) beside it.
"""
import os
import sys
import time

os.environ.setdefault("OPENCV_IO_ENABLE_OPENEXR", "1")
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
    # Mertens et al.'s exponents (OpenCV's default exposure weight is 0).
    tf, fusion = best(lambda: cv2.createMergeMertens(1.0, 1.0, 1.0).process(images))
    for name, r in (("Debevec", deb), ("Robertson", rob)):
        r = r.reshape(256, 3)
        nan = int(np.isnan(r).sum())
        mono = [bool(np.all(np.diff(r[:, c]) > 0)) for c in range(3)]
        print(f"{name}: {nan} NaN values; strictly increasing per channel (B, G, R): {mono}")
    lum = hdr[..., 2] * 0.2126 + hdr[..., 1] * 0.7152 + hdr[..., 0] * 0.0722
    lum = lum[lum > 0]
    print(f"CalibrateDebevec {td*1e3:.1f} ms, CalibrateRobertson {tr*1e3:.1f} ms, MergeDebevec {tm*1e3:.1f} ms "
          f"({len(images) * images[0].shape[0] * images[0].shape[1] / 1e6 / tm:.0f} Mpixel-frames/s); "
          f"merged range {np.log2(lum.max() / lum.min()):.1f} stops; MergeMertens {tf*1e3:.1f} ms")
    if out:
        png = np.clip(fusion * 255.0 + 0.5, 0, 255).astype(np.uint8)
        cv2.imwrite(os.path.join(os.path.dirname(out) or ".", "fusion.png"), png)
        cv2.imwrite(out, hdr)


if __name__ == "__main__":
    main(*sys.argv[1:])
