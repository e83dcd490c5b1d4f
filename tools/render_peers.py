"""Helpers the render comparison scripts share (tools/equal_time.py, tools/caustic_reference.py,
tools/luxcore_bdpt.py): a time-budgeted lumen render read back, and which pixels of a Mitsuba
scene's camera see one shape. Mitsuba must be imported with its variant set before calling them.
"""
import os, subprocess, tempfile, time
import numpy as np
import mitsuba as mi


def lumen_render(binary, scene_file, integrator, seconds):
    """`lumen render --time-budget`: the image, the wall time and the samples per pixel reached."""
    with tempfile.TemporaryDirectory() as d:
        out = os.path.join(d, 'x.exr')
        t = time.perf_counter()
        r = subprocess.run([binary, 'render', scene_file, '--integrator', integrator, '--time-budget', str(seconds),
                            '--out', out], capture_output=True, text=True, check=True)
        wall = time.perf_counter() - t
        spp = int(r.stderr.split(' spp')[0].rsplit(', ', 1)[-1])
        return np.array(mi.Bitmap(out))[..., :3], wall, spp


def pixels_seeing(scene, shape_id, sub=8):
    """The pixels any of sub × sub rays through their square meets the shape `shape_id` with."""
    sensor = scene.sensors()[0]
    w, h = sensor.film().crop_size()
    ys, xs, sy, sx = np.meshgrid(np.arange(h), np.arange(w), np.arange(sub), np.arange(sub), indexing='ij')
    fx = ((xs + (sx + 0.5) / sub) / w).ravel().astype(np.float32)
    fy = ((ys + (sy + 0.5) / sub) / h).ravel().astype(np.float32)
    rays, _ = sensor.sample_ray(0.0, 0.5, mi.Point2f(fx, fy), mi.Point2f(0.5, 0.5))
    si = scene.ray_intersect(rays)
    shape = [s for s in scene.shapes() if s.id() == shape_id][0]
    return np.array(si.is_valid() & (si.shape == mi.ShapePtr(shape))).reshape(h, w, sub * sub).any(axis=2)


def grow(mask, steps=1):
    """The mask with its 4-neighbours added, `steps` times."""
    for _ in range(steps):
        g = mask.copy()
        g[1:, :] |= mask[:-1, :]
        g[:-1, :] |= mask[1:, :]
        g[:, 1:] |= mask[:, :-1]
        g[:, :-1] |= mask[:, 1:]
        mask = g
    return mask
