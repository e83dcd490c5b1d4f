"""Equal-time error of lumen's integrators and Mitsuba 3's on one scene, against a reference.

Usage: $PEERS_PY tools/equal_time.py tests/data/mitsuba/caustic.xml \
           --reference tests/data/mitsuba/caustic.exr --region 58,48,90,66 --seconds 16 \
           [--lumen target/release/lumen] [--lumen-integrators path,light] [--mitsuba-integrators path,ptracer]

The scene file takes its integrator from a `$integrator` parameter (caustic.xml does). For each
Mitsuba integrator (llvm_ad_rgb), after compilation the sample count is scaled until one render
takes `seconds` within 10 %, and that render is kept; for each lumen integrator,
`lumen render --time-budget seconds`. Runs alternate between the two renderers. Prints, per run,
the wall time of the render, the samples per pixel reached and relMSE = mean((x − ref)²/(ref² +
0.01)) over the whole image and over the region [x0, y0, x1, y1) — the measure
`image::metrics::relmse` and the pipeline's render stage use. Mitsuba's seeds start at 1000, away
from the seeds 1..32 tools/mitsuba_reference.py renders references with. Mitsuba comes from the
peers virtual environment (../shared/tools/peers-venv.sh), never from lumen's dependencies.
"""
import argparse, os, time
import numpy as np
import mitsuba as mi

mi.set_variant('llvm_ad_rgb')
import drjit as dr
from render_peers import lumen_render


def relmse(x, ref, window=None):
    if window:
        x0, y0, x1, y1 = window
        x, ref = x[y0:y1, x0:x1], ref[y0:y1, x0:x1]
    return float(np.mean((x - ref) ** 2 / (ref ** 2 + 0.01)))


def mitsuba(scene_file, integrator, seconds, seed):
    scene = mi.load_file(scene_file, integrator=integrator)

    def render(spp, seed):
        t = time.perf_counter()
        img = mi.render(scene, spp=spp, seed=seed)
        dr.eval(img)
        dr.sync_thread()
        return img, time.perf_counter() - t

    # Compile, then scale the sample count until a render takes the budget within 10 %.
    render(4, seed)
    spp, wall = 64, render(64, seed)[1]
    for k in range(6):
        spp = max(1, int(spp * seconds / wall))
        img, wall = render(spp, seed + 1 + k)
        if abs(wall - seconds) < 0.1 * seconds:
            break
    return np.array(img)[..., :3], wall, spp


a = argparse.ArgumentParser()
a.add_argument('scene')
a.add_argument('--reference', required=True)
a.add_argument('--region', help='x0,y0,x1,y1')
a.add_argument('--seconds', type=float, default=16)
a.add_argument('--lumen', default='target/release/lumen')
a.add_argument('--lumen-integrators', default='path,light')
a.add_argument('--mitsuba-integrators', default='path,ptracer')
a.add_argument('--repeat', type=int, default=1)
o = a.parse_args()
ref = np.array(mi.Bitmap(o.reference))[..., :3]
window = [int(v) for v in o.region.split(',')] if o.region else None
runs = []
for k in range(o.repeat):
    for li, mi_int in zip(o.lumen_integrators.split(','), o.mitsuba_integrators.split(',')):
        for who, f in (('lumen ' + li, lambda: lumen_render(o.lumen, o.scene, li, o.seconds)),
                       ('mitsuba ' + mi_int, lambda: mitsuba(o.scene, mi_int, o.seconds, 1000 + 10 * k))):
            img, wall, spp = f()
            row = (who, wall, spp, relmse(img, ref), relmse(img, ref, window) if window else float('nan'))
            runs.append(row)
            print(f'{row[0]:<18} {row[1]:7.2f} s {row[2]:8d} spp  relMSE {row[3]:.3e}  region {row[4]:.3e}',
                  flush=True)
os._exit(0)
