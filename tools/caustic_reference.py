"""The whole-image reference of a caustic scene, tests/data/mitsuba/caustic.xml or
cornell-glass.xml: Mitsuba 3's particle tracer where it converges (everything but the glass seen
directly, which no light path reaches the camera through) and its path tracer where the camera
sees the glass.

Usage: $PEERS_PY tools/caustic_reference.py [--scene caustic] [--passes 32] [--spp 8192] [--out tests/data/mitsuba]
Reads SCENE.exr / SCENE_variance.exr (tools/mitsuba_reference.py SCENE: the ptracer) and
renders the path tracer in `passes` independent renders of `spp` samples; a pixel is the path
tracer's where any of 8 × 8 rays through its square meets the glass (the sphere's silhouette
and the pixels it touches), the particle tracer's elsewhere. Writes SCENE-full.exr and
SCENE-full_variance.exr (the variance of the mean of whichever render the pixel took). Mitsuba
comes from the peers virtual environment (../shared/tools/peers-venv.sh), never from lumen's
dependencies.
"""
import argparse, os
import numpy as np
import mitsuba as mi

mi.set_variant('llvm_ad_rgb')
import drjit as dr
from render_peers import grow, pixels_seeing

a = argparse.ArgumentParser()
a.add_argument('--scene', choices=['caustic', 'cornell-glass'], default='caustic')
a.add_argument('--passes', type=int, default=32)
a.add_argument('--spp', type=int, default=8192)
a.add_argument('--out', default='tests/data/mitsuba')
o = a.parse_args()
d = 'tests/data/mitsuba'
scene = mi.load_file(os.path.join(d, f'{o.scene}.xml'), integrator='path')
w, h = scene.sensors()[0].film().crop_size()
# Which pixels see the glass: 8 × 8 rays through each pixel's square, and their neighbours.
mask = grow(pixels_seeing(scene, 'glass'))
imgs = np.stack([np.array(mi.render(scene, spp=o.spp, seed=100 + k))[..., :3] for k in range(o.passes)])
path_mean, path_var = imgs.mean(axis=0), imgs.var(axis=0, ddof=1) / o.passes
pt_mean = np.array(mi.Bitmap(os.path.join(d, f'{o.scene}.exr')))[..., :3]
pt_var = np.array(mi.Bitmap(os.path.join(d, f'{o.scene}_variance.exr')))[..., :3]
mean = np.where(mask[..., None], path_mean, pt_mean).astype(np.float32)
var = np.where(mask[..., None], path_var, pt_var).astype(np.float32)
mi.util.write_bitmap(os.path.join(o.out, f'{o.scene}-full.exr'), mi.TensorXf(mean), write_async=False)
mi.util.write_bitmap(os.path.join(o.out, f'{o.scene}-full_variance.exr'), mi.TensorXf(var), write_async=False)
print(f'{o.scene}-full: {mask.sum()} of {w * h} pixels from {o.passes} × {o.spp} spp of path, mean {mean.reshape(-1, 3).mean(axis=0)}',
      flush=True)
os._exit(0)
