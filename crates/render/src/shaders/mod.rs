//! The built-in shaders, chosen by name (`--shader`): see [`Builtin`].

use std::f32::consts::PI;

use megaray_base::{Ray, Vec3};
use megaray_trace::Suspended;

use crate::material::Material;
use crate::settings::Builtin;
use crate::shader::{ShadeCtx, Shader, SurfaceHit};

mod path;
pub use path::path;

impl Shader for Builtin {
    fn shade(&self, ray: &Ray, hit: &SurfaceHit, ctx: &mut ShadeCtx<'_>) -> Result<Vec3, Suspended> {
        // What an area light emits, plus what every surface reflects (normals: shown alone).
        let emitted = if *self == Builtin::Normal { Vec3::ZERO } else { ctx.emitted(hit) };
        let reflected = match self {
            Builtin::Normal => Ok(hit.ns * 0.5 + 0.5),
            Builtin::Diffuse => diffuse(hit, ctx, ctx.material(hit).albedo),
            Builtin::Phong => phong(hit, ctx, &ctx.material(hit)),
            Builtin::Mirror => mirror(ray, hit, ctx, Vec3::splat(0.9)),
            Builtin::Glass => glass(ray, hit, ctx),
            Builtin::Ao => ao(hit, ctx),
            Builtin::Env => {
                let a = ctx.material(hit).albedo;
                ctx.env_direct(hit, |_| a / PI)
            }
            Builtin::Path => path(ray, hit, ctx),
            Builtin::Auto => {
                let m = ctx.material(hit);
                if m.opacity < 1.0 {
                    glass(ray, hit, ctx)
                } else if m.metallic >= 0.5 {
                    mirror(ray, hit, ctx, m.albedo)
                } else if m.specular != Vec3::ZERO && m.shininess > 0.0 {
                    phong(hit, ctx, &m)
                } else {
                    diffuse(hit, ctx, m.albedo)
                }
            }
        }?;
        Ok(emitted + reflected)
    }
}

/// Lambertian: ambient plus direct light.
pub fn diffuse(hit: &SurfaceHit, ctx: &mut ShadeCtx<'_>, albedo: Vec3) -> Result<Vec3, Suspended> {
    let f = albedo / PI;
    Ok(f * ctx.ambient() + ctx.direct(hit, |_| f)?)
}

/// Lambertian plus normalised Blinn-Phong highlights.
pub fn phong(hit: &SurfaceHit, ctx: &mut ShadeCtx<'_>, m: &Material) -> Result<Vec3, Suspended> {
    let (ks, ns) = if m.specular != Vec3::ZERO && m.shininess > 0.0 {
        (m.specular, m.shininess)
    } else {
        (Vec3::splat(0.3), 32.0)
    };
    let kd = m.albedo / PI;
    let wo = hit.wo;
    let n = hit.ns;
    let norm = (ns + 8.0) / (8.0 * PI);
    let brdf = |l: Vec3| {
        let h = (l + wo).normalize_or_zero();
        kd + ks * (norm * n.dot(h).max(0.0).powf(ns))
    };
    Ok(kd * ctx.ambient() + ctx.direct(hit, brdf)?)
}

fn reflect(d: Vec3, n: Vec3) -> Vec3 {
    d - n * (2.0 * d.dot(n))
}

/// A perfect mirror of reflectance `tint`.
pub fn mirror(ray: &Ray, hit: &SurfaceHit, ctx: &mut ShadeCtx<'_>, tint: Vec3) -> Result<Vec3, Suspended> {
    let d = ray.dir.normalize();
    let mut r = reflect(d, hit.ns);
    if r.dot(hit.ng) <= 0.0 {
        // The shading normal sends the ray into the surface: use the geometric one.
        r = reflect(d, hit.ng);
    }
    Ok(tint * ctx.trace(&ctx.spawn(hit, r))?)
}

/// Clear glass of index 1.5.
pub fn glass(ray: &Ray, hit: &SurfaceHit, ctx: &mut ShadeCtx<'_>) -> Result<Vec3, Suspended> {
    const IOR: f32 = 1.5;
    let d = ray.dir.normalize();
    let n = hit.ns; // faces the incoming ray
    let eta = if hit.front { 1.0 / IOR } else { IOR };
    let cos_i = (-d.dot(n)).clamp(0.0, 1.0);
    let sin2_t = eta * eta * (1.0 - cos_i * cos_i);
    let r0 = ((1.0 - IOR) / (1.0 + IOR)).powi(2);
    let fresnel = if sin2_t >= 1.0 { 1.0 } else { r0 + (1.0 - r0) * (1.0 - cos_i).powi(5) };
    if ctx.next_1d() < fresnel {
        return mirror(ray, hit, ctx, Vec3::ONE);
    }
    let cos_t = (1.0 - sin2_t).sqrt();
    let mut t = d * eta + n * (eta * cos_i - cos_t);
    if t.dot(hit.ng) >= 0.0 {
        t = d; // the shading normal disagrees with the geometry: pass straight through
    }
    ctx.trace(&ctx.spawn(hit, t.normalize()))
}

/// A unit vector perpendicular to `n`.
fn basis(n: Vec3) -> (Vec3, Vec3) {
    let sign = 1.0f32.copysign(n.z);
    let a = -1.0 / (sign + n.z);
    let b = n.x * n.y * a;
    (Vec3::new(1.0 + sign * n.x * n.x * a, sign * b, -sign * n.x), Vec3::new(b, sign + n.y * n.y * a, -n.y))
}

/// A cosine-distributed direction about `n` from `(u1, u2)`.
pub fn cosine_dir(n: Vec3, u1: f32, u2: f32) -> Vec3 {
    let (t, b) = basis(n);
    let r = u1.sqrt();
    let phi = 2.0 * PI * u2;
    (t * (r * phi.cos()) + b * (r * phi.sin()) + n * (1.0 - u1).max(0.0).sqrt()).normalize()
}

/// Ambient occlusion.
pub fn ao(hit: &SurfaceHit, ctx: &mut ShadeCtx<'_>) -> Result<Vec3, Suspended> {
    let k = ctx.settings().light_samples.max(1);
    let radius = ctx.settings().ao_radius * ctx.world().diagonal();
    let mut open = 0;
    for _ in 0..k {
        let (u1, u2) = ctx.next_2d();
        let d = cosine_dir(hit.ns, u1, u2);
        if d.dot(hit.ng) <= 0.0 {
            continue;
        }
        let mut r = ctx.spawn(hit, d);
        r.t_max = radius;
        if !ctx.occluded(&r)? {
            open += 1;
        }
    }
    Ok(ctx.material(hit).albedo * (open as f32 / k as f32))
}
