//! Mitsuba's BSDFs as lumen materials: `diffuse`, `conductor`, `roughconductor`,
//! `dielectric`, `roughdielectric`, `thindielectric`, `plastic`, `roughplastic`, `null` and
//! `twosided`, with named conductors and
//! indices of refraction (`named`).

use super::super::super::texture::{RoughnessSpec, TextureSpec};
use super::super::super::Error;
use super::super::file::MaterialSpec;
use super::named;
use super::props::{number, Color, Props};
use super::xml::Elem;

pub(super) fn lambertian(name: &str, albedo: TextureSpec) -> MaterialSpec {
    MaterialSpec {
        name: name.to_string(),
        kind: "lambertian".into(),
        albedo: Some(albedo),
        specular: None,
        exponent: None,
        distribution: None,
        alpha: None,
        eta: None,
        k: None,
        ior: None,
        nonlinear: None,
        emission: None,
        // Mitsuba's diffuse and conductors are black from behind unless wrapped in `twosided`.
        two_sided: Some(false),
    }
}

/// Mitsuba's `null`: no surface, only a medium's boundary.
pub(super) fn null(name: &str) -> MaterialSpec {
    MaterialSpec {
        kind: "null".into(),
        albedo: None,
        two_sided: None,
        ..lambertian(name, TextureSpec::Constant([1.0; 3]))
    }
}

pub(super) fn copy_material(m: &MaterialSpec, name: String, emission: [f64; 3]) -> MaterialSpec {
    MaterialSpec { name, emission: Some(emission), ..m.clone() }
}

/// An index of refraction: a number or one of Mitsuba's names.
fn ior(p: &Props, name: &str, default: &str) -> Result<f64, Error> {
    let Some(c) = p.find(name) else {
        return Ok(named::IORS.iter().find(|(n, _)| *n == default).map(|x| x.1).unwrap_or(1.0));
    };
    let v = c.attr("value").ok_or_else(|| c.error("needs `value`"))?;
    match c.tag.as_str() {
        "float" => number(c, v),
        "string" => named::IORS.iter().find(|(n, _)| *n == v).map(|x| x.1).ok_or_else(|| {
            let names: Vec<&str> = named::IORS.iter().map(|x| x.0).collect();
            c.error(format!("\"{v}\" is not a named index of refraction (known: {})", names.join(", ")))
        }),
        t => Err(c.error(format!("<{t}>: expected a <float> or a <string> name"))),
    }
}

/// A conductor's η and k: `material` (default "none", a perfect mirror) or `eta` and `k`.
fn complex_index(b: &Elem, p: &Props) -> Result<([f64; 3], [f64; 3]), Error> {
    let material = p.string("material")?;
    let eta = p.color("eta")?.map(|c| c.rgb(b, "eta")).transpose()?;
    let k = p.color("k")?.map(|c| c.rgb(b, "k")).transpose()?;
    match (material, eta, k) {
        (Some(_), Some(_), _) | (Some(_), _, Some(_)) => {
            Err(b.error("give `material` or `eta` and `k`, not both"))
        }
        (None, Some(eta), Some(k)) => Ok((eta, k)),
        (None, Some(_), None) | (None, None, Some(_)) => Err(b.error("give both `eta` and `k`")),
        (m, None, None) => {
            let m = m.unwrap_or_else(|| "none".into());
            if m == "none" {
                return Ok(([0.0; 3], [1.0; 3]));
            }
            named::CONDUCTORS.iter().find(|c| c.0 == m).map(|c| (c.1, c.2)).ok_or_else(|| {
                let names: Vec<&str> = named::CONDUCTORS.iter().map(|c| c.0).collect();
                b.error(format!(
                    "material \"{m}\" is not a named conductor (known: none, {})",
                    names.join(", ")
                ))
            })
        }
    }
}

/// A rough model's `distribution` (default beckmann, as Mitsuba's) and `alpha` (or equal
/// `alpha_u` and `alpha_v`; default 0.1).
fn microfacets(b: &Elem, p: &Props, m: &mut MaterialSpec) -> Result<(), Error> {
    let dist = p.string("distribution")?.unwrap_or_else(|| "beckmann".into());
    if dist != "ggx" && dist != "beckmann" {
        return Err(b.error(format!("distribution \"{dist}\": expected ggx or beckmann")));
    }
    m.distribution = Some(dist);
    let alpha = match (p.float("alpha")?, p.float("alpha_u")?, p.float("alpha_v")?) {
        (Some(a), None, None) => a,
        (None, Some(u), Some(v)) if u == v => u,
        (None, Some(_), Some(_)) => {
            return Err(b.unsupported("alpha_u ≠ alpha_v: lumen's microfacets are isotropic"))
        }
        (None, None, None) => 0.1,
        _ => return Err(b.error("give `alpha`, or both `alpha_u` and `alpha_v`")),
    };
    m.alpha = Some(RoughnessSpec::Constant(alpha));
    // Visible-normal sampling changes the noise, not the image.
    p.accept(&["sample_visible"]);
    Ok(())
}

/// A dielectric's or thin dielectric's relative index int_ior/ext_ior (default BK7 in air)
/// and its one tint: lumen tints reflection and transmission alike.
fn dielectric(b: &Elem, p: &Props) -> Result<(f64, [f64; 3]), Error> {
    let eta = relative_ior(b, p, "bk7")?;
    let r = p.color("specular_reflectance")?.map(|c| c.rgb(b, "specular_reflectance")).transpose()?;
    let t = p.color("specular_transmittance")?.map(|c| c.rgb(b, "specular_transmittance")).transpose()?;
    let tint = match (r, t) {
        (None, None) => [1.0; 3],
        (Some(a), None) | (None, Some(a)) if a == [1.0; 3] => a,
        (Some(a), Some(c)) if a == c => a,
        _ => return Err(b.unsupported(
            "different specular_reflectance and specular_transmittance: lumen's dielectrics tint both alike",
        )),
    };
    Ok((eta, tint))
}

/// int_ior / ext_ior (named or numeric; defaults `inside` and air), both positive.
fn relative_ior(b: &Elem, p: &Props, inside: &str) -> Result<f64, Error> {
    let int = ior(p, "int_ior", inside)?;
    let ext = ior(p, "ext_ior", "air")?;
    if !(int > 0.0 && ext > 0.0) {
        return Err(b.error(format!("int_ior {int}, ext_ior {ext}: expected positive indices")));
    }
    Ok(int / ext)
}

pub(super) fn bsdf(b: &Elem, name: String) -> Result<MaterialSpec, Error> {
    let p = Props::new(b);
    let mut m = lambertian(&name, TextureSpec::Constant([0.5; 3]));
    match b.plugin() {
        "diffuse" => {
            m.albedo = Some(p.color("reflectance")?.map_or(TextureSpec::Constant([0.5; 3]), Color::texture));
        }
        "twosided" => {
            let inner = p.objects("bsdf");
            p.finish("one nested bsdf")?;
            return match inner.as_slice() {
                [i] => {
                    let mut m = bsdf(i, name)?;
                    m.two_sided = None;
                    Ok(m)
                }
                [_, _] => Err(b.unsupported(
                    "a twosided with two different BSDFs: lumen's surfaces have one material on both sides",
                )),
                _ => Err(b.error("needs one nested <bsdf>")),
            };
        }
        "conductor" | "roughconductor" => {
            let (eta, k) = complex_index(b, &p)?;
            m.eta = Some(eta);
            m.k = Some(k);
            m.albedo = Some(TextureSpec::Constant(
                p.color("specular_reflectance")?
                    .map(|c| c.rgb(b, "specular_reflectance"))
                    .transpose()?
                    .unwrap_or([1.0; 3]),
            ));
            if b.plugin() == "conductor" {
                m.kind = "mirror".into();
            } else {
                m.kind = "conductor".into();
                microfacets(b, &p, &mut m)?;
            }
        }
        "roughdielectric" => {
            let (eta, tint) = dielectric(b, &p)?;
            m.kind = "rough-dielectric".into();
            m.two_sided = None;
            m.ior = Some(eta);
            m.albedo = Some(TextureSpec::Constant(tint));
            microfacets(b, &p, &mut m)?;
        }
        "null" => {
            p.finish("nothing")?;
            return Ok(null(&name));
        }
        "dielectric" => {
            let (eta, tint) = dielectric(b, &p)?;
            m.kind = "dielectric".into();
            m.two_sided = None;
            m.ior = Some(eta);
            m.albedo = Some(TextureSpec::Constant(tint));
        }
        "thindielectric" => {
            let (eta, tint) = dielectric(b, &p)?;
            m.kind = "thin-dielectric".into();
            m.two_sided = None;
            m.ior = Some(eta);
            m.albedo = Some(TextureSpec::Constant(tint));
        }
        "plastic" | "roughplastic" => {
            m.ior = Some(relative_ior(b, &p, "polypropylene")?);
            m.albedo = Some(p.color("diffuse_reflectance")?.map_or(TextureSpec::Constant([0.5; 3]), Color::texture));
            m.specular =
                p.color("specular_reflectance")?.map(|c| c.rgb(b, "specular_reflectance")).transpose()?;
            m.nonlinear = p.boolean("nonlinear")?;
            if b.plugin() == "plastic" {
                m.kind = "plastic".into();
            } else {
                m.kind = "rough-plastic".into();
                microfacets(b, &p, &mut m)?;
            }
        }
        other => {
            return Err(b.unsupported(format!(
            "bsdf \"{other}\": lumen reads diffuse, conductor, roughconductor, dielectric, roughdielectric, thindielectric, plastic, roughplastic, null and twosided"
        )))
        }
    }
    p.finish("reflectance (diffuse); material, eta, k, specular_reflectance, distribution, alpha (conductors); int_ior, ext_ior, specular_reflectance, specular_transmittance (dielectric, thindielectric), with distribution, alpha (roughdielectric); int_ior, ext_ior, diffuse_reflectance, specular_reflectance, nonlinear (plastic, with distribution, alpha for roughplastic)")?;
    Ok(m)
}
