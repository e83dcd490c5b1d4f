//! Mitsuba's media as lumen's `[[media]]`: `homogeneous` with `sigma_t` and `albedo` (Mitsuba's
//! defaults 1 and 0.75), or `sigma_a` and `sigma_s`, each a colour or a `constvolume`, times
//! `scale`; the phase function `isotropic` or `hg` (`g`).

use super::super::super::Error;
use super::super::file::MediumSpec;
use super::props::{Color, Props};
use super::xml::Elem;

/// A coefficient: a colour, or a `constvolume` holding one.
fn coefficient(p: &Props, name: &str) -> Result<Option<[f64; 3]>, Error> {
    let Some(c) = p.find(name) else { return Ok(None) };
    if c.tag != "volume" {
        return p.color(name)?.map(|v| v.rgb(c, name)).transpose();
    }
    match c.plugin() {
        "constvolume" => {
            let q = Props::new(c);
            let v = q.color("value")?.map_or(Ok([1.0; 3]), |v: Color| v.rgb(c, "value"))?;
            q.finish("value")?;
            Ok(Some(v))
        }
        "gridvolume" => Err(c.unsupported(
            "a gridvolume: lumen's media are homogeneous so far (give a constant or a constvolume)",
        )),
        other => Err(c.unsupported(format!("volume \"{other}\": lumen reads constvolume"))),
    }
}

pub(super) fn medium(e: &Elem, name: String) -> Result<MediumSpec, Error> {
    let p = Props::new(e);
    match e.plugin() {
        "homogeneous" => {}
        "heterogeneous" => return Err(e.unsupported(
            "medium \"heterogeneous\": lumen's media are homogeneous so far (volume grids are not read yet)",
        )),
        other => return Err(e.unsupported(format!("medium \"{other}\": lumen reads homogeneous"))),
    }
    let (sigma_t, albedo) = (coefficient(&p, "sigma_t")?, coefficient(&p, "albedo")?);
    let (sigma_a, sigma_s) = (coefficient(&p, "sigma_a")?, coefficient(&p, "sigma_s")?);
    let mut spec = MediumSpec { name, sigma_t, albedo, sigma_a, sigma_s, scale: p.float("scale")?, g: None };
    match (sigma_a, sigma_s) {
        (None, None) => {
            // Mitsuba's defaults.
            spec.sigma_t = Some(sigma_t.unwrap_or([1.0; 3]));
            spec.albedo = Some(albedo.unwrap_or([0.75; 3]));
        }
        (Some(_), Some(_)) if sigma_t.is_none() && albedo.is_none() => {}
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
    // samples them. Whether σt varies by channel is read from the values themselves.
    p.accept(&["sample_emitters", "has_spectral_extinction"]);
    p.finish("sigma_t, albedo, sigma_a, sigma_s, scale, phase")?;
    Ok(spec)
}
