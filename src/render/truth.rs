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
