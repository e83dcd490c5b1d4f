"""Renders one Mitsuba 3 scene file once, for timing against `lumen render` on the same file.

Usage: $PEERS_PY tools/mitsuba_render.py SCENE.xml [--spp 4096] [--variant llvm_ad_rgb] [--out img.exr]
Time the whole process (import, scene load, the llvm variant's compilation and the render), as
`lumen render SCENE.xml --spp N` is timed. Mitsuba comes from the peers virtual environment
(../shared/tools/peers-venv.sh), never from lumen's dependencies.
"""
import argparse, os
import mitsuba as mi

a = argparse.ArgumentParser()
a.add_argument('scene')
a.add_argument('--spp', type=int, default=4096)
a.add_argument('--variant', default='llvm_ad_rgb')
a.add_argument('--out')
o = a.parse_args()
mi.set_variant(o.variant)
import drjit as dr
scene = mi.load_file(o.scene)
img = mi.render(scene, spp=o.spp, seed=1)
dr.eval(img)
dr.sync_thread()
if o.out:
    mi.util.write_bitmap(o.out, img, write_async=False)
# Leave at once: drjit's thread pool can keep the interpreter from exiting.
os._exit(0)
