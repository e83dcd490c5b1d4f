#!/usr/bin/env python3
"""Intel Open Image Denoise on the inputs `lumen bench denoise --out DIR` wrote, beside lumen.

    python tools/oidn_compare.py DIR NAME REFERENCE.exr [--spp 4,16,64]

For each sample count N it reads DIR/NAME-Nspp.exr with its feature_albedo and
feature_normal buffers, runs OIDN's RT filter (hdr, quality high) with and without them, and
prints relMSE = mean((x - ref)^2 / (ref^2 + 0.01)) against REFERENCE and the filter's time
(best of three calls, after one warm-up that loads the network). Needs pyoidn, numpy and
openexr (../shared/tools/peers-venv.sh installs them); OIDN is measured against, never
depended on.
"""
import argparse
import time

import numpy as np
import OpenEXR
import pyoidn


def read(path):
    with OpenEXR.File(str(path)) as f:
        ch = f.channels()
        if "RGB" in ch:
            return np.ascontiguousarray(ch["RGB"].pixels, dtype=np.float32)
        return np.stack([ch[c].pixels for c in "RGB"], axis=-1).astype(np.float32)


def relmse(x, ref):
    return float(np.mean((x.astype(np.float64) - ref) ** 2 / (ref.astype(np.float64) ** 2 + 0.01)))


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("dir")
    ap.add_argument("name")
    ap.add_argument("reference")
    ap.add_argument("--spp", default="4,16,64")
    a = ap.parse_args()
    ref = read(a.reference)
    print(f"{a.name}: OIDN {pyoidn.__version__ if hasattr(pyoidn, '__version__') else ''} relMSE against {a.reference}\n")
    print("| spp | image | relMSE | filter time (s) |")
    print("|---:|---|---:|---:|")
    for n in [int(t) for t in a.spp.split(",")]:
        base = f"{a.dir}/{a.name}-{n}spp"
        color = read(base + ".exr")
        albedo = read(base + ".feature_albedo.exr")
        normal = read(base + ".feature_normal.exr")
        for label, aux in [("oidn", (None, None)), ("oidn + albedo, normal", (albedo, normal))]:
            pyoidn.denoise(color, aux[0], aux[1], hdr=True)
            best = float("inf")
            for _ in range(3):
                t = time.perf_counter()
                out = pyoidn.denoise(color, aux[0], aux[1], hdr=True)
                best = min(best, time.perf_counter() - t)
            print(f"| {n} | {label} | {relmse(np.asarray(out), ref):.3e} | {best:.3f} |")


if __name__ == "__main__":
    main()
