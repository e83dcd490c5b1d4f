//! Mitsuba's media as lumen's `[[media]]`: `homogeneous` with `sigma_t` and `albedo` (Mitsuba's
//! defaults 1 and 0.75), or `sigma_a` and `sigma_s`, each a colour or a `constvolume`, times
//! `scale`; `heterogeneous` with `sigma_t` a `gridvolume` (a `.vol` file, `to_world`,
//! `use_grid_bbox`) and a constant `albedo`; the phase function `isotropic` or `hg` (`g`).

use super::super::super::Error;
use super::super::file::{MediumSpec, TransformSpec};
use super::props::rows;
use super::props::{Color, Props};
use super::xml::Elem;

/// A coefficient: a colour, a `constvolume` holding one, or (where `grid` is given, for a
/// heterogeneous medium's σt) a `gridvolume`, whose file, placement and box go into `grid`.
fn coefficient(
    p: &Props,
    name: &str,
    mut grid: Option<(&mut MediumSpec, &dyn Fn(&Elem, &str) -> Result<String, Error>)>,
) -> Result<Option<[f64; 3]>, Error> {
    let Some(c) = p.find(name) else { return Ok(None) };
    if c.tag != "volume" {
        return p.color(name)?.map(|v| v.rgb(c, name)).transpose();
    }
    let q = Props::new(c);
    match c.plugin() {
        "constvolume" => {
            let v = q.color("value")?.map_or(Ok([1.0; 3]), |v: Color| v.rgb(c, "value"))?;
            q.finish("value")?;
            Ok(Some(v))
        }
        "gridvolume" => {
            let Some((spec, file)) = grid.as_mut() else {
                return Err(c.unsupported(format!(
                    "a gridvolume for `{name}`: lumen's heterogeneous media take a grid for sigma_t only"
                )));
            };
            let f = q.string("filename")?.ok_or_else(|| c.error("needs `filename`"))?;
            spec.grid = Some(file(c, &f)?);
            spec.grid_transform = q
                .transform("to_world")?
                .map(|m| TransformSpec { matrix: Some(rows(&m)), ..Default::default() });
            spec.grid_bbox = q.boolean("use_grid_bbox")?.filter(|&b| b);
            if let Some(t) = q.string("filter_type")?.filter(|t| t != "trilinear") {
                return Err(c.unsupported(format!("filter_type \"{t}\": lumen's grids are trilinear")));
            }
            // How the grid is stored and looked up, not what it holds.
            q.accept(&["raw", "accel", "wrap_mode"]);
            q.finish("filename, to_world, use_grid_bbox, filter_type")?;
            Ok(Some([1.0; 3]))
        }
        other => Err(c.unsupported(format!("volume \"{other}\": lumen reads constvolume and gridvolume"))),
    }
}

pub(super) fn medium(
    e: &Elem,
    name: String,
    file: &dyn Fn(&Elem, &str) -> Result<String, Error>,
) -> Result<MediumSpec, Error> {
    let p = Props::new(e);
    let mut spec = MediumSpec {
        name,
        sigma_t: None,
        albedo: None,
        sigma_a: None,
        sigma_s: None,
        scale: p.float("scale")?,
        g: None,
        grid: None,
        grid_transform: None,
        grid_bbox: None,
        noise: None,
    };
    let heterogeneous = match e.plugin() {
        "homogeneous" => false,
        "heterogeneous" => true,
        other => {
            return Err(
                e.unsupported(format!("medium \"{other}\": lumen reads homogeneous and heterogeneous"))
            )
        }
    };
    let sigma_t = if heterogeneous {
        let found = coefficient(&p, "sigma_t", Some((&mut spec, file)))?;
        if spec.grid.is_none() {
            return Err(e.error("a heterogeneous medium needs `sigma_t` as a <volume type=\"gridvolume\">"));
        }
        found
    } else {
        coefficient(&p, "sigma_t", None)?
    };
    let albedo = coefficient(&p, "albedo", None)?;
    let (sigma_a, sigma_s) = (coefficient(&p, "sigma_a", None)?, coefficient(&p, "sigma_s", None)?);
    spec.sigma_a = sigma_a;
    spec.sigma_s = sigma_s;
    match (sigma_a, sigma_s) {
        (None, None) => {
            // Mitsuba's defaults.
            spec.sigma_t = Some(sigma_t.unwrap_or([1.0; 3]));
            spec.albedo = Some(albedo.unwrap_or([0.75; 3]));
        }
        (Some(_), Some(_)) if sigma_t.is_none() && albedo.is_none() && !heterogeneous => {}
        _ => return Err(e.error("give `sigma_t` and `albedo`, or `sigma_a` and `sigma_s`")),
    }
    let phases = p.objects("phase");
    spec.g = match phases.as_slice() {
        [] => None,
        [ph] => {
            let q = Props::new(ph);
            let g = match ph.plugin() {
                "isotropic" => None,
                "hg" => Some(q.float("g")?.unwrap_or(0.8)),
                other => {
                    return Err(ph.unsupported(format!("phase \"{other}\": lumen reads isotropic and hg")))
                }
            };
            q.finish("g (hg)")?;
            g
        }
        _ => return Err(e.error("has more than one <phase>")),
    };
    // Whether emitters are sampled from inside changes the noise, not the image; lumen always
    // samples them. Whether σt varies by channel is read from the values themselves, and the
    // majorant from the grid.
    p.accept(&[
        "sample_emitters",
        "has_spectral_extinction",
        "majorant_resolution_factor",
        "majorant_factor",
    ]);
    p.finish("sigma_t, albedo, sigma_a, sigma_s, scale, phase")?;
    Ok(spec)
}
