//! The `path` shader: global illumination by path tracing.
//!
//! At every surface a path meets, direct light comes by next-event estimation from the
//! environment (the `--env` map or the constant sky colour, the sun of a procedural sky
//! included): `light_samples` shadow rays (at least one) toward directions drawn from the map
//! in proportion to its brightness ([`crate::EnvSampler`]; continuous, not the fixed virtual
//! lights of the direct-only shaders, whose fixed set would bias every point by what few of
//! them it sees). Then one bounce continues the path: a cosine-distributed direction for
//! diffuse and glossy surfaces (weighted by the BRDF over the density, so a glossy lobe is
//! estimated without bias), the mirror or refracted direction for mirrors and glass. A
//! diffuse or glossy bounce that escapes sees the environment too: the two estimates of the
//! same light are combined by multiple importance sampling (the power heuristic), a specular
//! bounce's by itself. The scene's area lights ([`crate::AreaLights`]) are sampled the same
//! way: `light_samples` points drawn on them in proportion to power, weighed against the
//! bounces that hit them ([`ShadeCtx::emitted`], which the built-in shaders add at every
//! hit). Russian roulette ends paths from the third surface on with probability
//! one minus the surface's reflectance, and `--max-depth` bounds them. Materials as the `auto`
//! shader reads them.

use std::f32::consts::PI;

use megaray_base::{Ray, Vec3};
use megaray_trace::Suspended;

use super::{cosine_dir, glass, mirror};
use crate::shader::{Bounce, ShadeCtx, SurfaceHit};

/// The radiance leaving `hit` toward the ray's origin.
pub fn path(ray: &Ray, hit: &SurfaceHit, ctx: &mut ShadeCtx<'_>) -> Result<Vec3, Suspended> {
    let m = ctx.material(hit);
    // Specular bounces are the built-ins' own: they trace on, and a miss sees the environment.
    if m.opacity < 1.0 {
        return glass(ray, hit, ctx);
    }
    if m.metallic >= 0.5 {
        return mirror(ray, hit, ctx, m.albedo);
    }
    let kd = m.albedo / PI;
    let wo = hit.wo;
    let n = hit.ns;
    let glossy = m.specular != Vec3::ZERO && m.shininess > 0.0;
    let (ks, ns) = (m.specular, m.shininess);
    let norm = (ns + 8.0) / (8.0 * PI);
    let brdf = |l: Vec3| {
        if glossy {
            let h = (l + wo).normalize_or_zero();
            kd + ks * (norm * n.dot(h).max(0.0).powf(ns))
        } else {
            kd
        }
    };
    let env = &ctx.world().environment().sampler;
    let k = ctx.settings().light_samples.max(1);
    let mut out = Vec3::ZERO;
    let u0 = ctx.next_1d();
    for j in 0..k {
        let (v, w) = ctx.next_2d();
        let Some((d, pdf_l)) = env.sample((j as f32 + u0) / k as f32, v, w) else { break };
        let cos = n.dot(d);
        if cos <= 0.0 || hit.ng.dot(d) <= 0.0 {
            continue;
        }
        let f = brdf(d);
        let pdf_b = cos / PI;
        let (pl, pb) = (k as f32 * pdf_l, pdf_b);
        let mis = pl * pl / (pl * pl + pb * pb);
        if !ctx.occluded(&ctx.spawn(hit, d))? {
            out += f * ctx.environment_pixel(d) * (cos * mis / pl);
        }
    }
    if let Some(area) = ctx.world().area_lights() {
        let u0 = ctx.next_1d();
        for j in 0..k {
            let (v, w) = ctx.next_2d();
            let Some(s) = area.sample(hit.p, (j as f32 + u0) / k as f32, v, w) else { continue };
            let cos = n.dot(s.dir);
            if cos <= 0.0 || hit.ng.dot(s.dir) <= 0.0 {
                continue;
            }
            let (pl, pb) = (k as f32 * s.pdf, cos / PI);
            let mis = pl * pl / (pl * pl + pb * pb);
            // From the point moved off the surface to just short of the light's point (aimed
            // anew: the move brings the light's plane nearer along the first direction).
            let mut shadow = ctx.spawn(hit, s.dir);
            let to = s.point - shadow.org;
            let len = to.length();
            shadow.dir = to / len;
            shadow.t_max = len * (1.0 - 1e-3);
            if len > 0.0 && !ctx.occluded(&shadow)? {
                out += brdf(s.dir) * s.radiance * (cos * mis / pl);
            }
        }
    }
    // The bounce: BRDF times cosine over the cosine density (cos / pi).
    let (u1, u2) = ctx.next_2d();
    let d = cosine_dir(n, u1, u2);
    if d.dot(hit.ng) <= 0.0 {
        return Ok(out);
    }
    let mut weight = brdf(d) * PI;
    if ctx.depth() >= 3 {
        let q = weight.max_element().min(1.0);
        if ctx.next_1d() >= q {
            return Ok(out);
        }
        weight /= q;
    }
    // Where it escapes, the environment it sees, weighted against the light samples.
    let (pb, pl) = (n.dot(d).max(0.0) / PI, k as f32 * env.pdf(d));
    let mis = if pb > 0.0 { pb * pb / (pb * pb + pl * pl) } else { 0.0 };
    out += weight * ctx.trace_bounce(&ctx.spawn(hit, d), Some(Bounce { env_weight: mis, pdf: pb }))?;
    Ok(out)
}
