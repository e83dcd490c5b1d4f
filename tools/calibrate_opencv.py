"""OpenCV's chessboard calibration, timed as `lumen bench calibrate` times lumen's.

The same three steps on the same photographs, with the settings of lumen's `opencv` feature
(src/cv.rs): findChessboardCorners (adaptive threshold, normalised image), cornerSubPix 5x5
(30 iterations or 1e-4), calibrateCamera (30 iterations or machine epsilon). Images are
decoded before timing; each step is the best of --repeat runs, as lumen's bench reports.

    python tools/calibrate_opencv.py --images '../shared/data/calibration/opencv-left/*.jpg'
"""

import argparse
import glob
import sys
import time

import cv2
import numpy as np


def best_of(repeat, f):
    best, out = float("inf"), None
    for _ in range(repeat):
        t = time.perf_counter()
        out = f()
        best = min(best, time.perf_counter() - t)
    return best, out


def main():
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--images", required=True, help="a quoted glob pattern")
    ap.add_argument("--board", default="9x6", help="inner corners as COLSxROWS")
    ap.add_argument("--repeat", type=int, default=5)
    a = ap.parse_args()
    cols, rows = (int(v) for v in a.board.lower().split("x"))
    files = sorted(glob.glob(a.images))
    if not files:
        sys.exit(f"{a.images}: no image matches")
    images = []
    for f in files:
        img = cv2.imread(f, cv2.IMREAD_GRAYSCALE)
        if img is None:
            sys.exit(f"{f}: cannot read it")
        images.append(img)
    flags = cv2.CALIB_CB_ADAPTIVE_THRESH | cv2.CALIB_CB_NORMALIZE_IMAGE
    sub = (cv2.TERM_CRITERIA_COUNT + cv2.TERM_CRITERIA_EPS, 30, 1e-4)

    def detect():
        found = []
        for img in images:
            ok, c = cv2.findChessboardCorners(img, (cols, rows), flags)
            if ok:
                found.append(cv2.cornerSubPix(img, c, (5, 5), (-1, -1), sub))
        return found

    detect_s, found = best_of(a.repeat, detect)
    board = np.zeros((cols * rows, 3), np.float32)
    board[:, :2] = np.mgrid[0:cols, 0:rows].T.reshape(-1, 2)
    h, w = images[0].shape
    crit = (cv2.TERM_CRITERIA_COUNT + cv2.TERM_CRITERIA_EPS, 30, np.finfo(float).eps)
    calib_s, out = best_of(
        a.repeat, lambda: cv2.calibrateCamera([board] * len(found), found, (w, h), None, None, criteria=crit)
    )
    print(
        f"| OpenCV {cv2.__version__} (Python, {cv2.getNumThreads()} threads) | {len(found)} | "
        f"{detect_s * 1e3:.1f} | {calib_s * 1e3:.1f} | {(detect_s + calib_s) * 1e3:.1f} | {out[0]:.4f} |"
    )


if __name__ == "__main__":
    main()
