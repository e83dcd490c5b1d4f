"""COLMAP (pycolmap) on a folder of photographs with a known pinhole K, timed per phase, and
its cameras compared with Strecha-format ground truth, for comparison with `lumen sfm`.

Usage (the peers' virtual environment, ../shared/tools/peers-venv.sh):
    $PEERS_PY tools/sfm_colmap.py ../shared/data/sfm/herz-jesu-p8 [threads] [MODEL]

With MODEL (SIMPLE_PINHOLE, SIMPLE_RADIAL, …) K.txt is not read: COLMAP guesses the focal
length (1.2 × the longer side) and refines it and the model's extra parameters, as
`lumen sfm` without --camera. MODEL=PARAMS (for example OPENCV=960,960,512,384,-0.12,0,0,0,
COLMAP's pixel centres) gives the camera instead, held fixed, as `lumen sfm --camera` with
distortion.

Prints extraction, matching and mapping times, registered images, points, the pairwise
relative rotation errors (median, max) against gt_dense_cameras/, and with MODEL the camera
it ended with.
"""
import os
import sys
import tempfile
import time

import numpy as np
import pycolmap


def gt(path):
    v = [float(x) for x in open(path).read().split()]
    # The file's six digits projected onto the nearest rotation, then world-to-camera.
    u, _, vt = np.linalg.svd(np.array(v[12:21]).reshape(3, 3))
    return (u @ vt).T


def angle_deg(r):
    """atan2(|axial vector|, trace - 1): precise at small angles, where arccos is not."""
    v = np.array([r[2, 1] - r[1, 2], r[0, 2] - r[2, 0], r[1, 0] - r[0, 1]])
    return np.degrees(np.arctan2(np.linalg.norm(v), np.trace(r) - 1))


def main(root, threads="2", model=None):
    images = os.path.join(root, "images")
    work = tempfile.mkdtemp()
    db = os.path.join(work, "database.db")
    opts = pycolmap.FeatureExtractionOptions()
    opts.num_threads = int(threads)
    reader = pycolmap.ImageReaderOptions()
    fixed = model is not None and "=" in model
    if fixed:
        reader.camera_model, reader.camera_params = model.split("=", 1)
        model = None
    elif model:
        reader.camera_model = model
    else:
        k = [float(x) for x in open(os.path.join(images, "K.txt")).read().split()]
        reader.camera_model = "PINHOLE"
        # COLMAP's pixel centres are at +0.5.
        reader.camera_params = f"{k[0]},{k[4]},{k[2] + 0.5},{k[5] + 0.5}"
    t = time.time()
    pycolmap.extract_features(db, images, camera_mode=pycolmap.CameraMode.SINGLE, reader_options=reader, extraction_options=opts, device=pycolmap.Device.cpu)
    t_ext = time.time() - t
    t = time.time()
    mopts = pycolmap.FeatureMatchingOptions()
    mopts.num_threads = int(threads)
    pycolmap.match_exhaustive(db, matching_options=mopts, device=pycolmap.Device.cpu)
    t_match = time.time() - t
    t = time.time()
    popts = pycolmap.IncrementalPipelineOptions()
    popts.num_threads = int(threads)
    popts.ba_refine_focal_length = bool(model)
    popts.ba_refine_principal_point = False
    popts.ba_refine_extra_params = bool(model)
    maps = pycolmap.incremental_mapping(db, images, work, options=popts)
    t_map = time.time() - t
    rec = max(maps.values(), key=lambda r: r.num_reg_images())
    rots = {}
    for img in rec.images.values():
        if img.has_pose:
            rots[img.name] = img.cam_from_world().rotation.matrix()
    names = sorted(rots)
    errs = []
    for a in range(len(names)):
        for b in range(a + 1, len(names)):
            ra, rb = rots[names[a]], rots[names[b]]
            ta = gt(os.path.join(root, "gt_dense_cameras", names[a] + ".camera"))
            tb = gt(os.path.join(root, "gt_dense_cameras", names[b] + ".camera"))
            e = (rb @ ra.T) @ (tb @ ta.T).T
            errs.append(angle_deg(e))
    errs = np.sort(errs)
    print(f"COLMAP {pycolmap.__version__}: extraction {t_ext:.2f} s, matching {t_match:.2f} s, mapping {t_map:.2f} s; "
          f"registered {rec.num_reg_images()}, points {rec.num_points3D()}; "
          f"rotation error median {np.median(errs):.4f}°, max {errs[-1]:.4f}°")
    if model:
        for cam in rec.cameras.values():
            print(f"camera {cam.model.name} {list(cam.params)}")


if __name__ == "__main__":
    main(*sys.argv[1:])
