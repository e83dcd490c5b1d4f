"""Renders Mitsuba 3 references for lumen's comparison scenes and the variance of their mean.

Usage: $PEERS_PY tools/mitsuba_reference.py glossy-spheres [--passes 32] [--spp 512] [--out tests/data/mitsuba]
Writes NAME.exr (the mean of `passes` independent renders of `spp` samples, box pixel filter,
linear RGB) and NAME_variance.exr (the variance of that mean: the passes' sample variance /
passes). Each scene is tests/data/mitsuba/NAME.xml, the lumen scene file
pipelines/scenes/NAME.toml written in Mitsuba's terms (the XML says how each part was
matched); lumen renders the same XML in tests/render_mitsuba.rs. Mitsuba comes from the peers
virtual environment (../shared/tools/peers-venv.sh), never from lumen's dependencies.
"""
import argparse, os
import numpy as np
import mitsuba as mi

mi.set_variant('llvm_ad_rgb')


def write_sky(path):
    """The 64 × 33 latitude-longitude sky of data/envmaps/sky.exr: a blue gradient, a sun of
    peak 400 two texels wide at (u, v) = (0.3, 0.3), a dim brown ground below the horizon."""
    w, h = 64, 33
    u = np.arange(w)[None, :] / w
    v = np.arange(h)[:, None] / (h - 1)
    sky = np.stack([0.3 + 0.4 * v, 0.45 + 0.3 * v, 0.9 + 0 * v], -1) * np.ones((h, w, 1))
    ground = np.array([0.12, 0.09, 0.06])
    img = np.where((v > 0.5)[..., None], ground, sky)
    du = np.minimum(np.abs(u - 0.3), 1 - np.abs(u - 0.3)) * w
    dv = (v - 0.3) * (h - 1)
    img = img + 400 * np.exp(-(du ** 2 + dv ** 2) / 2.0)[..., None] * np.array([1.0, 0.9, 0.75])
    mi.Bitmap(img.astype(np.float32)).write(path)


def write_smoke(path):
    """tests/data/mitsuba/smoke.vol: a 24 × 16 × 24 one-channel grid over [0, 1]³, three soft
    blobs of density (peak 1) in Mitsuba's .vol format (x fastest)."""
    nx, ny, nz = 24, 16, 24
    z, y, x = np.meshgrid((np.arange(nz) + 0.5) / nz, (np.arange(ny) + 0.5) / ny,
                          (np.arange(nx) + 0.5) / nx, indexing='ij')
    d = np.zeros_like(x)
    for (cx, cy, cz, r) in [(0.35, 0.4, 0.4, 0.22), (0.65, 0.55, 0.6, 0.18), (0.5, 0.3, 0.7, 0.12)]:
        d += np.exp(-((x - cx) ** 2 + (y - cy) ** 2 + (z - cz) ** 2) / (2 * r * r))
    d = np.clip(d, 0, 1).astype('<f4')
    header = b'VOL' + bytes([3]) + np.array([1, nx, ny, nz, 1], '<i4').tobytes() \
        + np.array([0, 0, 0, 1, 1, 1], '<f4').tobytes()
    with open(path, 'wb') as f:
        f.write(header + d.tobytes())


SCENES = ['glossy-spheres', 'sphere-light', 'glass-environment', 'envmap-spheres', 'depth-of-field',
          'media-fog-box', 'media-haze', 'media-glass', 'media-lamp-in-fog', 'media-smoke-sky',
          'media-smoke-grid', 'plastic-pane', 'rough-glass', 'envmap-turned', 'rough-plastic', 'showcase', 'caustic',
          'cornell-glass']

a = argparse.ArgumentParser()
a.add_argument('scene', choices=SCENES)
a.add_argument('--passes', type=int, default=32)
a.add_argument('--spp', type=int, default=512)
a.add_argument('--out', default='tests/data/mitsuba')
a.add_argument('--write-sky', action='store_true', help='first write data/envmaps/sky.exr')
a.add_argument('--write-smoke', action='store_true', help='first write tests/data/mitsuba/smoke.vol')
o = a.parse_args()
if o.write_sky:
    os.makedirs('data/envmaps', exist_ok=True)
    write_sky('data/envmaps/sky.exr')
if o.write_smoke:
    write_smoke('tests/data/mitsuba/smoke.vol')
scene = mi.load_file(os.path.join('tests/data/mitsuba', f'{o.scene}.xml'))
imgs = np.stack([np.array(mi.render(scene, spp=o.spp, seed=k + 1)) for k in range(o.passes)])
mean, var = imgs.mean(axis=0), imgs.var(axis=0, ddof=1) / o.passes
os.makedirs(o.out, exist_ok=True)
mi.util.write_bitmap(os.path.join(o.out, f'{o.scene}.exr'), mi.TensorXf(mean.astype(np.float32)), write_async=False)
mi.util.write_bitmap(os.path.join(o.out, f'{o.scene}_variance.exr'), mi.TensorXf(var.astype(np.float32)), write_async=False)
print(f'{o.scene}: {o.passes} × {o.spp} spp, mean {mean.reshape(-1, 3).mean(axis=0)}', flush=True)
# Leave at once: drjit's thread pool can keep the interpreter from exiting.
os._exit(0)
