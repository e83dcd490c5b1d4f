"""Equal-time comparison on Mitsuba 3's Cornell box: time and RMSE against the 8192-spp reference.

Usage: $PEERS_PY tools/mitsuba_convergence.py [--variant llvm_ad_rgb|scalar_rgb] [--sampler independent]
       [--spp 16,64,256] [--reference ../shared/data/scenes/cornell-box/reference.exr]
Prints one Markdown row per sample count: spp, seconds of the render call (after a warm-up
render for the llvm variant's kernel compilation), M paths/s and the RMSE over all pixel
channels against the reference — the same figures `lumen bench convergence` prints, so the two
can be read at equal time. The scene is mi.cornell_box() at 256 × 256 with a box filter and the
path integrator at max depth 8, as ../shared/tools/mitsuba_cornell.py times it. Mitsuba comes
from the peers virtual environment (../shared/tools/peers-venv.sh), never from lumen's
dependencies.
"""
import argparse, os, time
import numpy as np
import mitsuba as mi

a = argparse.ArgumentParser()
a.add_argument('--variant', default='llvm_ad_rgb')
a.add_argument('--sampler', default='independent')
a.add_argument('--spp', default='16,64,256')
a.add_argument('--reference', default='../shared/data/scenes/cornell-box/reference.exr')
o = a.parse_args()
mi.set_variant(o.variant)
import drjit as dr

d = mi.cornell_box()
d['sensor']['film'].update({'width': 256, 'height': 256, 'rfilter': {'type': 'box'}})
d['sensor']['sampler'] = {'type': o.sampler}
d['integrator'] = {'type': 'path', 'max_depth': 8}
scene = mi.load_dict(d)
ref = np.array(mi.Bitmap(o.reference), dtype=np.float64)[..., :3]
if o.variant.startswith('llvm'):
    img = mi.render(scene, spp=4); dr.eval(img); dr.sync_thread()
print(f'mitsuba {mi.__version__} {o.variant}, {o.sampler} sampler')
print('| spp | time (s) | M paths/s | RMSE |')
print('|---:|---:|---:|---:|')
for spp in [int(s) for s in o.spp.split(',')]:
    t = time.time()
    img = mi.render(scene, spp=spp, seed=7); dr.eval(img); dr.sync_thread()
    dt = time.time() - t
    rmse = np.sqrt(np.mean((np.array(img, dtype=np.float64)[..., :3] - ref) ** 2))
    print(f'| {spp} | {dt:.2f} | {256 * 256 * spp / dt / 1e6:.2f} | {rmse:.5f} |', flush=True)
# Leave at once: drjit's thread pool can keep the interpreter from exiting.
os._exit(0)
