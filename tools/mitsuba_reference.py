"""Renders Mitsuba 3 references for lumen's comparison scenes and the variance of their mean.

Usage: $PEERS_PY tools/mitsuba_reference.py glossy-spheres [--passes 32] [--spp 512] [--out tests/data/mitsuba]
Writes NAME.exr (the mean of `passes` independent renders of `spp` samples, box pixel filter,
linear RGB) and NAME_variance.exr (the variance of that mean: the passes' sample variance /
passes). Each scene here is the lumen scene file pipelines/scenes/NAME.toml written in
Mitsuba's terms; how each part was matched is said beside it. Mitsuba comes from the peers
virtual environment (../shared/tools/peers-venv.sh), never from lumen's dependencies.
"""
import argparse, os
import numpy as np
import mitsuba as mi

mi.set_variant('llvm_ad_rgb')
T = mi.ScalarTransform4f


def rgb(v):
    return {'type': 'rgb', 'value': v}


def base(target):
    """Integrator, 64×64 camera from (0, 1.2, 4) and the grey floor both scenes share."""
    return {
        'type': 'scene',
        # Mitsuba's depth counts the camera hit as 1, as lumen's max_depth does.
        'integrator': {'type': 'path', 'max_depth': 6},
        # lumen's fov_deg spans the smaller side, and its pixel (i, j) integrates the box
        # [i − ½, i + ½) around the centre: Mitsuba's box filter over pixel (i, j).
        'sensor': {'type': 'perspective', 'fov': 40, 'fov_axis': 'smaller',
                   'to_world': T().look_at(origin=[0, 1.2, 4], target=target, up=[0, 1, 0]),
                   'film': {'type': 'hdrfilm', 'width': 64, 'height': 64, 'rfilter': {'type': 'box'},
                            'pixel_format': 'rgb'}},
        # The floor quad: a rectangle ([-1, 1]², normal +z) turned to face +y, 6 × 6.
        'floor': {'type': 'rectangle', 'to_world': T().rotate([1, 0, 0], -90).scale(3),
                  'bsdf': {'type': 'diffuse', 'reflectance': rgb([0.5, 0.5, 0.5])}},
    }


def glossy_spheres():
    return base([0, 0.4, 0]) | {
        # The lamp: 1 × 1 at height 3 facing down, black, emitting 10 from its front only.
        'lamp': {'type': 'rectangle',
                 'to_world': T().translate([0, 3, 0.5]).rotate([1, 0, 0], 90).scale(0.5),
                 'bsdf': {'type': 'diffuse', 'reflectance': rgb([0, 0, 0])},
                 'emitter': {'type': 'area', 'radiance': rgb([10, 10, 10])}},
        # roughconductor with RGB η, k as lumen's conductor; specular_reflectance 1 = albedo 1.
        'gold': {'type': 'sphere', 'center': [-0.55, 0.5, 0], 'radius': 0.5,
                 'bsdf': {'type': 'roughconductor', 'distribution': 'ggx', 'alpha': 0.2,
                          'eta': rgb([0.143, 0.374, 1.442]), 'k': rgb([3.983, 2.385, 1.603])}},
        'copper': {'type': 'sphere', 'center': [0.55, 0.5, 0], 'radius': 0.5,
                   'bsdf': {'type': 'roughconductor', 'distribution': 'beckmann', 'alpha': 0.3,
                            'eta': rgb([0.2, 0.92, 1.1]), 'k': rgb([3.9, 2.45, 2.14])}},
    }


def sphere_light():
    return base([0, 0.5, 0]) | {
        # A sphere emitter radiates from its outside, as an emissive sphere in lumen.
        'lamp': {'type': 'sphere', 'center': [0.6, 1.5, 0.4], 'radius': 0.25,
                 'bsdf': {'type': 'diffuse', 'reflectance': rgb([0, 0, 0])},
                 'emitter': {'type': 'area', 'radiance': rgb([8, 7, 6])}},
        'copper': {'type': 'sphere', 'center': [-0.5, 0.5, 0], 'radius': 0.5,
                   'bsdf': {'type': 'roughconductor', 'distribution': 'ggx', 'alpha': 0.15,
                            'eta': rgb([0.2, 0.92, 1.1]), 'k': rgb([3.9, 2.45, 2.14])}},
        'clay': {'type': 'sphere', 'center': [0.6, 0.35, 0.3], 'radius': 0.35,
                 'bsdf': {'type': 'diffuse', 'reflectance': rgb([0.6, 0.3, 0.2])}},
    }


def glass_environment():
    scene = base([0, 0.4, 0]) | {
        # lumen's `ior` is η_inside/η_outside: int_ior 1.5 in vacuum (ext_ior 1).
        'glass': {'type': 'sphere', 'center': [-0.6, 0.5, 0.2], 'radius': 0.45,
                  'bsdf': {'type': 'dielectric', 'int_ior': 1.5, 'ext_ior': 1.0}},
        # lumen's `mirror` with η, k: Mitsuba's smooth `conductor`.
        'gold': {'type': 'sphere', 'center': [0.55, 0.45, -0.3], 'radius': 0.45,
                 'bsdf': {'type': 'conductor',
                          'eta': rgb([0.143, 0.374, 1.442]), 'k': rgb([3.983, 2.385, 1.603])}},
        'clay': {'type': 'sphere', 'center': [0.45, 0.25, 0.7], 'radius': 0.25,
                 'bsdf': {'type': 'diffuse', 'reflectance': rgb([0.6, 0.3, 0.2])}},
        'sky': {'type': 'constant', 'radiance': rgb([1.0, 0.9, 0.8])},
    }
    scene['integrator']['max_depth'] = 8
    return scene


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


def envmap_spheres():
    scene = base([0, 0.4, 0]) | {
        # lumen's `map` + `scale`: Mitsuba's envmap, whose (u, v) convention lumen follows
        # (render::envmap), world y up, no rotation.
        'sky': {'type': 'envmap', 'filename': 'data/envmaps/sky.exr', 'scale': 0.5},
        'copper': {'type': 'sphere', 'center': [-0.55, 0.45, 0], 'radius': 0.45,
                   'bsdf': {'type': 'roughconductor', 'distribution': 'ggx', 'alpha': 0.25,
                            'eta': rgb([0.2, 0.92, 1.1]), 'k': rgb([3.9, 2.45, 2.14])}},
        'mirror': {'type': 'sphere', 'center': [0.55, 0.45, -0.2], 'radius': 0.45,
                   'bsdf': {'type': 'conductor'}},
        'clay': {'type': 'sphere', 'center': [0.2, 0.25, 0.75], 'radius': 0.25,
                 'bsdf': {'type': 'diffuse', 'reflectance': rgb([0.6, 0.3, 0.2])}},
    }
    return scene


def depth_of_field():
    # envmap-spheres through a thin lens focused on the clay sphere: lumen's aperture_radius
    # and focus_distance (along the optical axis) are Mitsuba's thinlens parameters.
    scene = envmap_spheres()
    scene['sensor']['type'] = 'thinlens'
    scene['sensor']['aperture_radius'] = 0.08
    scene['sensor']['focus_distance'] = 3.3
    return scene


SCENES = {'glossy-spheres': glossy_spheres, 'sphere-light': sphere_light,
          'glass-environment': glass_environment, 'envmap-spheres': envmap_spheres,
          'depth-of-field': depth_of_field}

a = argparse.ArgumentParser()
a.add_argument('scene', choices=sorted(SCENES))
a.add_argument('--passes', type=int, default=32)
a.add_argument('--spp', type=int, default=512)
a.add_argument('--out', default='tests/data/mitsuba')
a.add_argument('--write-sky', action='store_true', help='first write data/envmaps/sky.exr')
o = a.parse_args()
if o.write_sky:
    os.makedirs('data/envmaps', exist_ok=True)
    write_sky('data/envmaps/sky.exr')
scene = mi.load_dict(SCENES[o.scene]())
imgs = np.stack([np.array(mi.render(scene, spp=o.spp, seed=k + 1)) for k in range(o.passes)])
mean, var = imgs.mean(axis=0), imgs.var(axis=0, ddof=1) / o.passes
os.makedirs(o.out, exist_ok=True)
mi.util.write_bitmap(os.path.join(o.out, f'{o.scene}.exr'), mi.TensorXf(mean.astype(np.float32)), write_async=False)
mi.util.write_bitmap(os.path.join(o.out, f'{o.scene}_variance.exr'), mi.TensorXf(var.astype(np.float32)), write_async=False)
print(f'{o.scene}: {o.passes} × {o.spp} spp, mean {mean.reshape(-1, 3).mean(axis=0)}', flush=True)
# Leave at once: drjit's thread pool can keep the interpreter from exiting.
os._exit(0)
