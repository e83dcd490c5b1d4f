//! Ground-truth images ("AOVs") from one ray through each pixel centre (OpenCV integer pixel
//! coordinates), written beside the render as `NAME.<aov>.exr`:
//!
//! | aov            | channels | meaning                                                         |
//! |----------------|----------|-----------------------------------------------------------------|
//! | depth          | Y        | camera-frame z of the first hit (scene units); 0 where no hit    |
//! | normal         | R G B    | world-frame unit geometric normal facing the camera; 0 no hit    |
//! | normal_camera  | R G B    | the same normal in the OpenCV camera frame (x right, y down, z forward) |
//! | albedo         | R G B    | diffuse albedo at the hit                                        |
//! | position       | R G B    | world-frame hit point                                            |
//! | id             | Y        | object id (1-based, names in `NAME.ids.json`); 0 is background   |

use super::geometry::Ray;
use super::scene::Scene;
use crate::image::Image;
use glam::{DVec2, DVec3, Vec3A};

pub const AOV_NAMES: [&str; 6] = ["depth", "normal", "normal_camera", "albedo", "position", "id"];

pub struct Truth {
    pub depth: Image,
    pub normal: Image,
    pub normal_camera: Image,
    pub albedo: Image,
    pub position: Image,
    pub id: Image,
}

impl Truth {
    pub fn get(&self, name: &str) -> Option<&Image> {
        Some(match name {
            "depth" => &self.depth,
            "normal" => &self.normal,
            "normal_camera" => &self.normal_camera,
            "albedo" => &self.albedo,
            "position" => &self.position,
            "id" => &self.id,
            _ => return None,
        })
    }
}

/// Truth images over the pixel window `crop` ([x0, y0, x1, y1), whole image when `None`).
pub fn truth(scene: &Scene, crop: Option<[u32; 4]>) -> Truth {
    let (w, h) = (scene.camera.width, scene.camera.height);
    let [x0, y0, x1, y1] = crop.unwrap_or([0, 0, w, h]);
    let (fw, fh) = (x1 - x0, y1 - y0);
    let mut t = Truth {
        depth: Image::new(fw, fh, 1),
        normal: Image::new(fw, fh, 3),
        normal_camera: Image::new(fw, fh, 3),
        albedo: Image::new(fw, fh, 3),
        position: Image::new(fw, fh, 3),
        id: Image::new(fw, fh, 1),
    };
    let pose = scene.t_world_cam;
    let cam_from_world = pose.inverse();
    for j in 0..fh {
        for i in 0..fw {
            let px = DVec2::new((x0 + i) as f64, (y0 + j) as f64);
            let Some((o, d)) = scene.camera_ray(px) else {
                continue;
            };
            let ray = Ray { origin: Vec3A::from(o.as_vec3()), dir: Vec3A::from(d.as_vec3()) };
            let Some(hit) = scene.bvh.intersect(&ray, 0.0, f32::INFINITY) else {
                continue;
            };
            let s = scene.surface(&ray, &hit);
            let n = if s.n.dot(ray.dir) > 0.0 { -s.n } else { s.n };
            let p_world = DVec3::from(Vec3A::to_array(&s.p).map(f64::from));
            let p_cam = cam_from_world.transform_point(p_world);
            let n_world = DVec3::from(n.to_array().map(f64::from));
            let n_cam = cam_from_world.transform_vector(n_world);
            let albedo = scene.albedo(s.material, &hit, s.p);
            t.depth.pixel_mut(i, j)[0] = p_cam.z as f32;
            t.normal.pixel_mut(i, j).copy_from_slice(&n.to_array());
            t.normal_camera.pixel_mut(i, j).copy_from_slice(&n_cam.as_vec3().to_array());
            t.albedo.pixel_mut(i, j).copy_from_slice(&albedo.to_array());
            t.position.pixel_mut(i, j).copy_from_slice(&s.p.to_array());
            t.id.pixel_mut(i, j)[0] = s.object_id as f32;
        }
    }
    t
}

/// The mean of the surface normal over each pixel's footprint, in the OpenCV camera frame and
/// normalised: `k`×`k` rays spread evenly over the pixel's square (centre ± 0.5 px, the
/// film's box filter), each normal turned towards the camera. This is the normal a
/// Lambertian pixel's brightness is linear in (the pixel integrates ρ·l·n over its square),
/// so it is the truth for photometric stereo on a faceted mesh, where the normal at the
/// centre alone can be a facet away. With each mean comes the largest angle (degrees)
/// between it and a ray's normal: large where the pixel straddles an occlusion edge or a
/// crease, which no single normal describes. `None` where a ray misses every object.
pub fn footprint_normals(scene: &Scene, pixels: &[(u32, u32)], k: u32) -> Vec<Option<(DVec3, f64)>> {
    use rayon::prelude::*;
    let cam_from_world = scene.t_world_cam.inverse();
    pixels
        .par_iter()
        .map(|&(x, y)| {
            let mut normals = Vec::with_capacity((k * k) as usize);
            for sy in 0..k {
                for sx in 0..k {
                    let off = |s: u32| (s as f64 + 0.5) / k as f64 - 0.5;
                    let px = DVec2::new(x as f64 + off(sx), y as f64 + off(sy));
                    let (o, d) = scene.camera_ray(px)?;
                    let ray = Ray { origin: Vec3A::from(o.as_vec3()), dir: Vec3A::from(d.as_vec3()) };
                    let hit = scene.bvh.intersect(&ray, 0.0, f32::INFINITY)?;
                    let n = scene.surface(&ray, &hit).n;
                    let n = if n.dot(ray.dir) > 0.0 { -n } else { n };
                    normals.push(cam_from_world.transform_vector(DVec3::from(n.to_array().map(f64::from))));
                }
            }
            let mean = normals.iter().sum::<DVec3>().try_normalize()?;
            let spread = normals.iter().map(|n| n.dot(mean).clamp(-1.0, 1.0).acos()).fold(0.0, f64::max);
            Some((mean, spread.to_degrees()))
        })
        .collect()
}

/// Per pixel (row-major over the whole image), whether any of `k`×`k` rays spread over its
/// square sees emission directly: an emitter's emitting side, or the environment past the
/// scene. A render limited to one segment (`max_depth = 1`) may be non-black only there.
/// The rays are the pinhole's (`Scene::camera_ray`), so `None` for a scene with a thin lens.
pub fn emitter_footprint(scene: &Scene, k: u32) -> Option<Vec<bool>> {
    use rayon::prelude::*;
    if scene.lens.is_some() {
        return None;
    }
    let (w, h) = (scene.camera.width, scene.camera.height);
    let sees = |px: DVec2| -> bool {
        let Some((o, d)) = scene.camera_ray(px) else { return false };
        let ray = Ray { origin: Vec3A::from(o.as_vec3()), dir: Vec3A::from(d.as_vec3()) };
        match scene.bvh.intersect(&ray, 0.0, f32::INFINITY) {
            None => scene.environment(ray.dir).is_some(),
            Some(hit) => {
                let surf = scene.surface(&ray, &hit);
                scene.materials[surf.material as usize].emission.is_some() && surf.n.dot(-ray.dir) > 0.0
            }
        }
    };
    Some(
        (0..w * h)
            .into_par_iter()
            .map(|i| {
                let (x, y) = (i % w, i / w);
                let off = |s: u32| (s as f64 + 0.5) / k as f64 - 0.5;
                (0..k * k).any(|s| sees(DVec2::new(x as f64 + off(s % k), y as f64 + off(s / k))))
            })
            .collect(),
    )
}
