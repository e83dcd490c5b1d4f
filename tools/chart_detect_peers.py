"""Finds the ColorChecker in photographs with lumen and with two peers, and compares them.

Usage: $PEERS_PY tools/chart_detect_peers.py [--lumen target/release/lumen]
       [--truth tests/data/chart-photos/corners.csv] [--photos ../shared/data/color/photos] [--repeat 3]

For each photograph: whether each detector found the chart, its corner error against the
hand-checked truth (the outer corners of the 6 x 4 cell grid, corner 0 by patch 1 "dark skin";
the error is the largest of the four corners' distances, in pixels and as a share of the
chart's diagonal), whether its patch order is right (corner 0 where the truth's is), and its
time per image (the median of --repeat runs; decoding excluded for all three: lumen's time is
the `seconds` its JSON reports, the peers' the call on an image already in memory).

The peers, from the peers virtual environment (../shared/tools/peers-venv.sh), never lumen's
dependencies:
- OpenCV's mcc module (CCheckerDetector, MCC24). Its 24 patch quadrilaterals, in chart order,
  give patch centres; a homography from the cell centres (col + 1/2, row + 1/2) to them gives
  the cell grid's corners in lumen's convention.
- colour-checker-detection (detect_colour_checkers_segmentation): its quadrilateral is the
  cell grid it warps to a 6 x 4 rectangle of swatches, in its working image (turned to
  landscape and resized to 1440 wide), mapped back to the photograph here.
"""
import argparse, csv, json, os, subprocess, sys, tempfile, time, warnings
import numpy as np
import cv2

warnings.filterwarnings("ignore")
a = argparse.ArgumentParser()
a.add_argument("--lumen", default="target/release/lumen")
a.add_argument("--truth", default="tests/data/chart-photos/corners.csv")
a.add_argument("--photos", default="../shared/data/color/photos")
a.add_argument("--repeat", type=int, default=3)
o = a.parse_args()

import colour_checker_detection as ccd

truth = {}
with open(o.truth) as f:
    for r in csv.DictReader(f):
        truth[r["image"]] = np.array([float(r[k]) for k in ["x1", "y1", "x2", "y2", "x3", "y3", "x4", "y4"]]).reshape(4, 2)


def grid_corners_from_centres(centres):
    cells = np.float32([[c % 6 + 0.5, c // 6 + 0.5] for c in range(24)])
    H, _ = cv2.findHomography(cells, np.float32(centres), 0)
    return cv2.perspectiveTransform(np.float32([[[0, 0], [6, 0], [6, 4], [0, 4]]]), H)[0]


def mcc(img):
    d = cv2.mcc.CCheckerDetector.create()
    if not d.process(img, 1):
        return None
    c = d.getBestColorChecker()
    polys = np.array(c.getColorCharts()).reshape(24, 4, 2)
    return grid_corners_from_centres(polys.mean(axis=1))


def colour_checker_detection(img):
    rgb = cv2.cvtColor(img, cv2.COLOR_BGR2RGB).astype(np.float32) / 255
    found = ccd.detect_colour_checkers_segmentation(rgb, additional_data=True)
    if not found:
        return None
    q = np.array(found[0].quadrilateral, dtype=np.float64)
    # Its rectangle's corners are (1440, 0), (1440, 960), (0, 960), (0, 0): cell-grid (6, 0),
    # (6, 4), (0, 4), (0, 0).
    q = np.array([q[3], q[0], q[1], q[2]])
    h0, w0 = img.shape[:2]
    portrait = w0 < h0
    width = h0 if portrait else w0
    ratio = width / 1440
    q = (q + 0.5) * ratio - 0.5
    if portrait:  # turned 90 degrees clockwise: (x, y) in the turned image is (h0 - 1 - y, x)
        q = np.stack([q[:, 1], h0 - 1 - q[:, 0]], axis=1)
    return q


def lumen(path):
    with tempfile.TemporaryDirectory() as t:
        out = os.path.join(t, "chart.json")
        r = subprocess.run([o.lumen, "color", "detect", "--image", path, "--out", out], capture_output=True, text=True)
        if r.returncode != 0:
            return None, None
        j = json.load(open(out))
        return np.array(j["corners"]), j["seconds"]


def score(corners, t):
    if corners is None:
        return None
    d = np.linalg.norm(corners - t, axis=1)
    diag = np.linalg.norm(t[0] - t[2])
    # Corner error whatever the patch order, and whether the order is the truth's.
    rolled = [np.linalg.norm(np.roll(corners, k, axis=0) - t, axis=1).max() for k in range(4)]
    return {"max_px": float(d.max()), "max_share": float(d.max() / diag), "any_order_px": float(min(rolled)),
            "order_right": bool(int(np.argmin(rolled)) == 0)}


rows = []
for name in sorted(truth):
    path = os.path.join(o.photos, name)
    img = cv2.imread(path)
    row = {"image": name}
    for label, fn in [("mcc", mcc), ("ccd", colour_checker_detection)]:
        times, corners = [], None
        for _ in range(o.repeat):
            t0 = time.perf_counter()
            corners = fn(img)
            times.append(time.perf_counter() - t0)
        row[label] = {"score": score(corners, truth[name]), "seconds": float(np.median(times))}
    times, corners = [], None
    for _ in range(o.repeat):
        corners, s = lumen(path)
        times.append(s if s is not None else float("nan"))
    row["lumen"] = {"score": score(corners, truth[name]), "seconds": float(np.median(times))}
    rows.append(row)


def cell(r):
    s = r["score"]
    if s is None:
        return "not found | | | %.3f" % r["seconds"]
    return "%.1f px (%.2f %%) | %.1f px | %s | %.3f" % (s["max_px"], 100 * s["max_share"], s["any_order_px"],
                                                         "yes" if s["order_right"] else "no", r["seconds"])


print("| image | detector | corner error, max (share of diagonal) | in any order | order right | seconds |")
print("|---|---|---|---|---|---|")
for r in rows:
    for label, name in [("lumen", "lumen"), ("mcc", "OpenCV mcc"), ("ccd", "colour-checker-detection")]:
        print("| %s | %s | %s |" % (r["image"], name, cell(r[label])))
for label, name in [("lumen", "lumen"), ("mcc", "OpenCV mcc"), ("ccd", "colour-checker-detection")]:
    found = [r[label]["score"] for r in rows if r[label]["score"] is not None]
    secs = [r[label]["seconds"] for r in rows]
    worst = max((s["max_px"] for s in found), default=float("nan"))
    med = float(np.median([s["max_px"] for s in found])) if found else float("nan")
    right = sum(s["order_right"] for s in found)
    print("%s: found %d of %d, order right %d, corner error median %.1f px, worst %.1f px, median %.3f s per image"
          % (name, len(found), len(rows), right, med, worst, float(np.median(secs))))
