"""Equal-time error of lumen's bidirectional path tracer and light tracer against LuxCore's
(BIDIRCPU, LIGHTCPU), on the caustic scene built of triangles both renderers read.

Usage: $PEERS_PY tools/luxcore_bdpt.py --out /tmp/lux [--seconds 16] [--repeat 2]
           [--lumen target/release/lumen] [--reference-spp 131072] [--luxcore-reference-seconds 480]

LuxCore has no analytic sphere, so the scene of tests/data/mitsuba/caustic.xml is rebuilt from
meshes: the 6 × 6 grey floor as two triangles, the glass sphere (η 1.5, radius 0.5) as an
icosphere of 81 920 flat faces and the lamp (radius 0.05, radiance 400, 380, 340) as one of
1 280. The script writes the meshes as PLY and `caustic-mesh.xml`, a Mitsuba 3 scene of them
(`face_normals`: both Mitsuba and LuxCore would otherwise smooth the facets, lumen shades with
face normals), into --out. lumen renders that XML as it is; LuxCore gets the same triangles
through `Scene.DefineMesh`, the same camera (look-at, 40° field of view on the square film),
a box pixel filter one pixel wide and maximum depth 8 for eye and light subpaths.

Each renderer is measured against its own converged render, so that the error is its noise
and not the two renderers' pixel conventions (LuxCore's image lands about a row lower than
Mitsuba's and lumen's): lumen against Mitsuba 3's particle tracer on the same XML
(`reference.exr`, --reference-spp samples in 16 independent renders), LuxCore against its own
light tracer (`luxcore-reference.exr`, --luxcore-reference-seconds); both are kept in --out and
reused. The two references' image means are printed side by side: the same scene gives the
same mean. A light tracer converges everywhere but on the glass seen directly, so the error is
measured over the caustic's pixels, window [58, 48, 90, 66), and over the image without the
pixels that see the glass (from Mitsuba's ray casts, widened by two pixels for LuxCore's
offset), each without the glass's pixels.

Each run renders for --seconds: lumen with `--time-budget`, LuxCore with `batch.halttime` on two
threads; the runs alternate. Printed per run: the wall time, the samples per pixel reached and
relMSE = mean((x − ref)²/(ref² + 0.01)), the measure `image::metrics::relmse` uses. LuxCore and
Mitsuba come from the peers virtual environment (../shared/tools/peers-venv.sh), never from
lumen's dependencies.
"""
import argparse, os, subprocess, sys, tempfile, time
import numpy as np


def icosphere(subdivisions):
    t = (1 + 5 ** 0.5) / 2
    v = [(-1, t, 0), (1, t, 0), (-1, -t, 0), (1, -t, 0), (0, -1, t), (0, 1, t), (0, -1, -t), (0, 1, -t),
         (t, 0, -1), (t, 0, 1), (-t, 0, -1), (-t, 0, 1)]
    v = [np.array(p, float) / np.linalg.norm(p) for p in v]
    f = [(0, 11, 5), (0, 5, 1), (0, 1, 7), (0, 7, 10), (0, 10, 11), (1, 5, 9), (5, 11, 4), (11, 10, 2),
         (10, 7, 6), (7, 1, 8), (3, 9, 4), (3, 4, 2), (3, 2, 6), (3, 6, 8), (3, 8, 9), (4, 9, 5),
         (2, 4, 11), (6, 2, 10), (8, 6, 7), (9, 8, 1)]
    for _ in range(subdivisions):
        mid, g = {}, []

        def m(a, b):
            k = (min(a, b), max(a, b))
            if k not in mid:
                p = v[a] + v[b]
                v.append(p / np.linalg.norm(p))
                mid[k] = len(v) - 1
            return mid[k]

        for a, b, c in f:
            ab, bc, ca = m(a, b), m(b, c), m(c, a)
            g += [(a, ab, ca), (b, bc, ab), (c, ca, bc), (ab, bc, ca)]
        f = g
    return np.array(v), np.array(f, dtype=np.int32)


def write_ply(path, v, f):
    with open(path, 'wb') as out:
        out.write((f'ply\nformat binary_little_endian 1.0\nelement vertex {len(v)}\n'
                   'property float x\nproperty float y\nproperty float z\n'
                   f'element face {len(f)}\nproperty list uchar int vertex_indices\nend_header\n').encode())
        out.write(v.astype('<f4').tobytes())
        rows = np.zeros(len(f), dtype=[('n', 'u1'), ('i', '<i4', 3)])
        rows['n'], rows['i'] = 3, f
        out.write(rows.tobytes())


CAMERA = dict(origin=(0, 2.0, 3.5), target=(0.2, 0.2, 0), up=(0, 1, 0), fov=40, size=96)
LAMP = np.array([400, 380, 340], float)


def meshes():
    floor_v = np.array([(-3, 0, -3), (3, 0, -3), (3, 0, 3), (-3, 0, 3)], float)
    floor_f = np.array([(0, 2, 1), (0, 3, 2)], dtype=np.int32)  # normal +y
    gv, gf = icosphere(6)
    lv, lf = icosphere(4)
    return {'floor': (floor_v, floor_f), 'glass': (gv * 0.5 + (0, 0.5, 0), gf),
            'lamp': (lv * 0.05 + (-1.8, 1.6, -0.4), lf)}


def write_scene(out):
    for name, (v, f) in meshes().items():
        write_ply(os.path.join(out, name + '.ply'), v, f)
    c = CAMERA
    xml = f"""<!-- The caustic scene of caustic.xml in triangles (tools/luxcore_bdpt.py writes it). -->
<scene version="3.0.0">
    <default name="integrator" value="ptracer"/>
    <default name="spp" value="256"/>
    <integrator type="$integrator"><integer name="max_depth" value="8"/></integrator>
    <sensor type="perspective">
        <float name="fov" value="{c['fov']}"/>
        <string name="fov_axis" value="smaller"/>
        <transform name="to_world">
            <lookat origin="{', '.join(map(str, c['origin']))}" target="{', '.join(map(str, c['target']))}" up="{', '.join(map(str, c['up']))}"/>
        </transform>
        <sampler type="independent"><integer name="sample_count" value="$spp"/></sampler>
        <film type="hdrfilm">
            <integer name="width" value="{c['size']}"/>
            <integer name="height" value="{c['size']}"/>
            <rfilter type="box"/>
            <string name="pixel_format" value="rgb"/>
        </film>
    </sensor>
    <shape type="ply" id="floor">
        <string name="filename" value="floor.ply"/>
        <boolean name="face_normals" value="true"/>
        <bsdf type="diffuse"><rgb name="reflectance" value="0.5"/></bsdf>
    </shape>
    <shape type="ply" id="glass">
        <string name="filename" value="glass.ply"/>
        <boolean name="face_normals" value="true"/>
        <bsdf type="dielectric">
            <float name="int_ior" value="1.5"/>
            <string name="ext_ior" value="vacuum"/>
        </bsdf>
    </shape>
    <shape type="ply" id="lamp">
        <string name="filename" value="lamp.ply"/>
        <boolean name="face_normals" value="true"/>
        <bsdf type="diffuse"><rgb name="reflectance" value="0"/></bsdf>
        <emitter type="area"><rgb name="radiance" value="{', '.join(map(str, LAMP))}"/></emitter>
    </shape>
</scene>
"""
    path = os.path.join(out, 'caustic-mesh.xml')
    with open(path, 'w') as fh:
        fh.write(xml)
    return path


def reference(xml, out, spp):
    """Mitsuba's particle tracer, 16 renders of spp/16; and the pixels that see the glass."""
    path = os.path.join(out, 'reference.exr')
    scene = mi.load_file(xml, integrator='ptracer')
    if not os.path.exists(path):
        imgs = [np.array(mi.render(scene, spp=spp // 16, seed=100 + k))[..., :3] for k in range(16)]
        mi.util.write_bitmap(path, mi.TensorXf(np.mean(imgs, axis=0).astype(np.float32)), write_async=False)
    # Widened by two pixels for LuxCore's offset (module docs).
    sees = grow(pixels_seeing(scene, 'glass'), 2)
    return np.array(mi.Bitmap(path))[..., :3], ~sees


def luxcore_reference(out, seconds):
    path = os.path.join(out, 'luxcore-reference.exr')
    if not os.path.exists(path):
        img, _, passes = luxcore('LIGHTCPU', seconds)
        print(f'LuxCore reference: {passes} passes of LIGHTCPU', flush=True)
        mi.util.write_bitmap(path, mi.TensorXf(img), write_async=False)
    return np.array(mi.Bitmap(path))[..., :3]


def luxcore(engine, seconds):
    """One LuxCore render in its own process: pyluxcore's allocator and Mitsuba's cannot share one."""
    with tempfile.TemporaryDirectory() as d:
        out = os.path.join(d, 'x.npy')
        t = time.perf_counter()
        r = subprocess.run([sys.executable, __file__, '--worker', engine, str(seconds), out], capture_output=True,
                           text=True)
        wall = time.perf_counter() - t
        if r.returncode != 0:
            raise SystemExit(f'LuxCore failed: {r.stderr[-2000:]}')
        passes = int(r.stdout.split()[-1])
        return np.load(out), wall, passes


def luxcore_worker(engine, seconds, out):
    import pyluxcore
    pyluxcore.Init(lambda s: None)
    c = CAMERA
    scene = pyluxcore.Scene()
    for name, (v, f) in meshes().items():
        scene.DefineMesh(name + '-mesh', [tuple(p) for p in v.tolist()], [tuple(t) for t in f.tolist()], None, None, None, None)
    v3 = lambda p: ' '.join(f'{x:.9g}' for x in p)
    scene.Parse(pyluxcore.Properties().SetFromString(f"""
scene.camera.type = "perspective"
scene.camera.lookat.orig = {v3(c['origin'])}
scene.camera.lookat.target = {v3(c['target'])}
scene.camera.up = {v3(c['up'])}
scene.camera.fieldofview = {c['fov']}
scene.materials.floor.type = "matte"
scene.materials.floor.kd = 0.5 0.5 0.5
scene.materials.glass.type = "glass"
scene.materials.glass.kr = 1 1 1
scene.materials.glass.kt = 1 1 1
scene.materials.glass.interiorior = 1.5
scene.materials.glass.exteriorior = 1.0
scene.materials.lamp.type = "matte"
scene.materials.lamp.kd = 0 0 0
scene.materials.lamp.emission = {v3(LAMP)}
scene.objects.floor.shape = "floor-mesh"
scene.objects.floor.material = "floor"
scene.objects.glass.shape = "glass-mesh"
scene.objects.glass.material = "glass"
scene.objects.lamp.shape = "lamp-mesh"
scene.objects.lamp.material = "lamp"
"""))
    config = pyluxcore.RenderConfig(pyluxcore.Properties().SetFromString(f"""
renderengine.type = "{engine}"
sampler.type = "RANDOM"
path.maxdepth = 8
light.maxdepth = 8
film.width = {c['size']}
film.height = {c['size']}
film.filter.type = "BOX"
film.filter.width = 0.25
native.threads.count = 2
batch.halttime = {seconds}
film.outputs.0.type = "RGB"
film.outputs.0.filename = "unused.exr"
"""), scene)
    session = pyluxcore.RenderSession(config)
    session.Start()
    while not session.HasDone():
        time.sleep(0.05)
        session.UpdateStats()
    session.Stop()
    stats = session.GetStats()
    img = np.zeros((c['size'], c['size'], 3), np.float32)
    session.GetFilm().GetOutputFloat(pyluxcore.FilmOutputType.RGB, img)
    np.save(out, img[::-1])  # LuxCore's film rows run bottom up
    print(int(stats.Get('stats.renderengine.pass').GetInt()), flush=True)
    os._exit(0)


def relmse(x, ref, mask):
    return float(np.mean(((x - ref) ** 2 / (ref ** 2 + 0.01))[mask]))


if len(sys.argv) == 5 and sys.argv[1] == '--worker':
    luxcore_worker(sys.argv[2], float(sys.argv[3]), sys.argv[4])
import mitsuba as mi

mi.set_variant('llvm_ad_rgb')
from render_peers import grow, lumen_render, pixels_seeing

a = argparse.ArgumentParser()
a.add_argument('--out', required=True)
a.add_argument('--seconds', type=float, default=16)
a.add_argument('--repeat', type=int, default=1)
a.add_argument('--lumen', default='target/release/lumen')
a.add_argument('--reference-spp', type=int, default=131072)
a.add_argument('--luxcore-reference-seconds', type=float, default=480)
a.add_argument('--pairs', default='bdpt:BIDIRCPU,light:LIGHTCPU')
o = a.parse_args()
os.makedirs(o.out, exist_ok=True)
xml = write_scene(o.out)
ref, outside_glass = reference(xml, o.out, o.reference_spp)
lux_ref = luxcore_reference(o.out, o.luxcore_reference_seconds)
caustic = np.zeros_like(outside_glass)
caustic[48:66, 58:90] = True
caustic &= outside_glass
print(f'image mean outside the glass: Mitsuba reference {ref[outside_glass].mean(axis=0)}, '
      f'LuxCore reference {lux_ref[outside_glass].mean(axis=0)}; over the caustic: '
      f'{ref[caustic].mean(axis=0)}, {lux_ref[caustic].mean(axis=0)}', flush=True)
for k in range(o.repeat):
    for pair in o.pairs.split(','):
        ours, theirs = pair.split(':')
        for who, f in (('lumen ' + ours, lambda: lumen_render(o.lumen, xml, ours, o.seconds)),
                       ('luxcore ' + theirs, lambda: luxcore(theirs, o.seconds))):
            img, wall, spp = f()
            r = lux_ref if who.startswith('luxcore') else ref
            if k == 0:
                mi.util.write_bitmap(os.path.join(o.out, who.replace(' ', '-') + '.exr'), mi.TensorXf(img),
                                     write_async=False)
            print(f'{who:<18} {wall:7.2f} s {spp:8d} spp  relMSE caustic {relmse(img, r, caustic):.3e}  '
                  f'outside the glass {relmse(img, r, outside_glass):.3e}  '
                  f'mean ratio {img[outside_glass].mean() / r[outside_glass].mean():.4f}', flush=True)
os._exit(0)
