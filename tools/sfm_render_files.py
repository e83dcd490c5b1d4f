"""Renders the courtyard arc of `pipelines/all.toml`'s sfm case as image files, with the true
cameras in the Strecha format beside them, so that `lumen sfm` and COLMAP
(`tools/sfm_colmap.py`) can be run and compared on the same files.

Usage (numpy is needed: the peers' virtual environment, ../shared/tools/peers-venv.sh):
    $PEERS_PY tools/sfm_render_files.py VIEWS OUT_DIR [LUMEN_BINARY] [SCENE]

SCENE is a file of pipelines/scenes (default sfm-courtyard.toml; sfm-courtyard-wide.toml is
the same through a lens with k1 = −0.12, whose K.txt then leaves the distortion out).

Writes OUT_DIR/images/view000.png … (`lumen render`, the scene's 8 spp, seed k + 1 for view
k), OUT_DIR/images/K.txt and OUT_DIR/gt_dense_cameras/<image>.camera: K, no distortion, the
camera-to-world rotation (OpenCV axes: x right, y down, z forward), the centre, the size.
The cameras are the sfm stage's: spaced evenly along a 40° arc 3.5 m from (0, 0.5, 0.6), at
height 1.3, each looking at that point.
"""
import math
import os
import re
import subprocess
import sys

import numpy as np

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))


def main(views, out, lumen=os.path.join(ROOT, "target/release/lumen"), scene_file="sfm-courtyard.toml"):
    n = int(views)
    os.makedirs(os.path.join(out, "images"), exist_ok=True)
    os.makedirs(os.path.join(out, "gt_dense_cameras"), exist_ok=True)
    scene_dir = os.path.join(ROOT, "pipelines/scenes")
    src = open(os.path.join(scene_dir, scene_file)).read()
    target, radius, height, arc = np.array([0.0, 0.5, 0.6]), 3.5, 1.3, 40.0
    fx, cx, cy, w, h = 960.0, 511.5, 383.5, 1024, 768
    with open(os.path.join(out, "images/K.txt"), "w") as f:
        f.write(f"{fx} 0 {cx}\n0 {fx} {cy}\n0 0 1\n")
    for k in range(n):
        phi = math.radians(-90 + arc * (k / (n - 1) - 0.5))
        o = [float(target[0] + radius * math.cos(phi)), float(target[1] + radius * math.sin(phi)), height]
        look = f"look_at = {{ origin = [{o[0]!r}, {o[1]!r}, {o[2]!r}], target = [0.0, 0.5, 0.6], up = [0.0, 0.0, 1.0] }}"
        scene = re.sub(r"look_at = \{[^}]*\}", look, src)
        scene = re.sub(r"(\[render\][^\[]*?)seed = \d+", lambda m: f"{m.group(1)}seed = {k + 1}", scene, count=1)
        path = os.path.join(out, f"scene{k:03}.toml")
        open(path, "w").write(scene)
        name = f"view{k:03}.png"
        subprocess.run([lumen, "render", path, "--out", os.path.join(out, "images", name)], check=True)
        z = target - np.array(o)
        z /= np.linalg.norm(z)
        x = np.cross(z, [0.0, 0.0, 1.0])
        x /= np.linalg.norm(x)
        y = np.cross(z, x)
        r = np.stack([x, y, z], axis=1)
        with open(os.path.join(out, "gt_dense_cameras", name + ".camera"), "w") as g:
            g.write(f"{fx} 0 {cx}\n0 {fx} {cy}\n0 0 1\n0 0 0\n")
            for row in r:
                g.write(" ".join(repr(float(v)) for v in row) + "\n")
            g.write(" ".join(repr(float(v)) for v in o) + "\n")
            g.write(f"{w} {h}\n")
    print(f"{n} views in {out}")


if __name__ == "__main__":
    main(*sys.argv[1:])
