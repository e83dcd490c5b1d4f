"""lumen surface against pymeshlab's APSS and RIMLS marching cubes on the same points.

Usage: $PEERS_PY tools/surface_pymeshlab.py [--lumen target/release/lumen] [--points 20000]
       [--noise 0.004] [--resolution 128] [--seed 3]

Samples a torus (R = 1, r = 0.4, uniform by area) with Gaussian noise along the normal, writes
it as a PLY without normals, and meshes it with lumen (apss and mls, normals estimated) and
with pymeshlab (normals for point clouds, 10 neighbours; then generate_marching_cubes_apss and
_rimls at the same grid resolution). For each: the RMS and largest distance of the mesh's
vertices to the true torus, whether every edge has two faces, the genus, and the wall time of
the meshing (lumen's whole process; pymeshlab's normal estimation and filter, the points already
loaded). Peers come from the peers virtual environment (../shared/tools/peers-venv.sh).
"""
import argparse, json, os, subprocess, tempfile, time
import numpy as np
import pymeshlab as ml

a = argparse.ArgumentParser()
a.add_argument("--lumen", default="target/release/lumen")
a.add_argument("--points", type=int, default=20000)
a.add_argument("--noise", type=float, default=0.004)
a.add_argument("--resolution", type=int, default=128)
a.add_argument("--seed", type=int, default=3)
o = a.parse_args()

rng = np.random.default_rng(o.seed)
pts = []
while len(pts) < o.points:
    u, v, t = rng.random(3) * [2 * np.pi, 2 * np.pi, 1]
    if t > (1 + 0.4 * np.cos(v)) / 1.4:
        continue
    n = np.array([np.cos(v) * np.cos(u), np.cos(v) * np.sin(u), np.sin(v)])
    c = np.array([np.cos(u), np.sin(u), 0.0])
    pts.append(c + (0.4 + o.noise * rng.standard_normal()) * n)
pts = np.array(pts)


def distance(v):
    q = np.sqrt(v[:, 0] ** 2 + v[:, 1] ** 2) - 1.0
    return np.sqrt(q ** 2 + v[:, 2] ** 2) - 0.4


def topology(faces):
    edges = {}
    for f in faces:
        for a_, b_ in ((f[0], f[1]), (f[1], f[2]), (f[2], f[0])):
            k = (min(a_, b_), max(a_, b_))
            edges[k] = edges.get(k, 0) + 1
    closed = all(c == 2 for c in edges.values())
    used = np.unique(faces)
    chi = len(used) - len(edges) + len(faces)
    return closed, (1 - chi // 2) if closed else None


def report(name, verts, faces, secs):
    d = distance(verts)
    closed, genus = topology(faces)
    print(f"| {name} | {np.sqrt(np.mean(d ** 2)):.2e} | {np.abs(d).max():.2e} | {'yes' if closed else 'no'} | {genus} | {secs:.2f} |")


print(f"torus R = 1, r = 0.4, {o.points} points, noise {o.noise} along the normal, grid {o.resolution} across")
print("| method | RMS distance | largest | closed | genus | seconds |")
print("|---|---:|---:|---|---:|---:|")
with tempfile.TemporaryDirectory() as t:
    src = os.path.join(t, "points.ply")
    with open(src, "wb") as f:
        f.write(b"ply\nformat binary_little_endian 1.0\nelement vertex %d\nproperty float x\nproperty float y\nproperty float z\nend_header\n" % len(pts))
        f.write(pts.astype("<f4").tobytes())
    for method in ["apss", "mls"]:
        out = os.path.join(t, f"lumen-{method}.ply")
        t0 = time.perf_counter()
        subprocess.run([o.lumen, "surface", "--points", src, "--out", out, "--method", method,
                        "--resolution", str(o.resolution)], check=True, capture_output=True)
        secs = time.perf_counter() - t0
        m = ml.MeshSet()
        m.load_new_mesh(out)
        report(f"lumen {method}", m.current_mesh().vertex_matrix(), m.current_mesh().face_matrix(), secs)
    for name, filt in [("apss", "generate_marching_cubes_apss"), ("rimls", "generate_marching_cubes_rimls")]:
        ms = ml.MeshSet()
        ms.load_new_mesh(src)
        t0 = time.perf_counter()
        ms.compute_normal_for_point_clouds(k=10)
        getattr(ms, filt)(resolution=o.resolution)
        secs = time.perf_counter() - t0
        mesh = ms.current_mesh()
        report(f"pymeshlab {name}", mesh.vertex_matrix(), mesh.face_matrix(), secs)
