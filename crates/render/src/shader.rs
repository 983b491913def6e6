//! The shader interface: what is called at each hit, and what it may do.
//!
//! A [`Shader`] gets the hit ([`SurfaceHit`]: the tracer's [`Hit`] plus position and
//! normals) and a [`ShadeCtx`] through which it fires rays (closest hit
//! [`ShadeCtx::intersect`], any hit [`ShadeCtx::occluded`], or [`ShadeCtx::trace`], which
//! shades the next hit recursively up to the depth limit), reads the surface's
//! [`Material`] (only when it asks: attributes stay out of traversal's way), draws its random
//! numbers and sums the lights ([`ShadeCtx::direct`]). Every ray goes through
//! [`megaray_trace::RayCaster`], so a paging tracer may answer [`Suspended`]: shaders pass it
//! on with `?`, and, since all their random numbers come from the (pixel, sample index)
//! sampler, the re-run sample fires the same rays.
//!
//! ```
//! use megaray_base::{Ray, Vec3};
//! use megaray_render::{ShadeCtx, Shader, SurfaceHit};
//! use megaray_trace::Suspended;
//!
//! /// Red where the light is seen, blue in shadow.
//! struct RedBlue;
//! impl Shader for RedBlue {
//!     fn shade(&self, _ray: &Ray, hit: &SurfaceHit, ctx: &mut ShadeCtx<'_>) -> Result<Vec3, Suspended> {
//!         let shadow = ctx.spawn(hit, ctx.settings().light.normalize());
//!         Ok(if ctx.occluded(&shadow)? { Vec3::Z } else { Vec3::X })
//!     }
//! }
//! ```

use megaray_base::{Ray, Vec3};
use megaray_scene::Scene;
use megaray_trace::{Cone, Hit, RayCaster, RayCone, Suspended};

use crate::env::DirLight;
use crate::material::{material_at, Material};
use crate::sampling::Sampler;
use crate::settings::RenderSettings;
use crate::world::World;

/// Called when a ray hits a surface; returns the radiance leaving the hit toward the ray's
/// origin. Implementations must be deterministic given the context's sampler (no other
/// source of randomness), and pass [`Suspended`] on.
pub trait Shader: Send + Sync {
    /// The radiance leaving `hit` back along `ray` (toward `-ray.dir`).
    fn shade(&self, ray: &Ray, hit: &SurfaceHit, ctx: &mut ShadeCtx<'_>) -> Result<Vec3, Suspended>;
}

/// A hit, with what nearly every shader needs computed: the point, the geometric and the
/// shading normal, both unit length and on the side the ray came from.
#[derive(Clone, Copy, Debug)]
pub struct SurfaceHit {
    /// The tracer's hit record.
    pub hit: Hit,
    /// The hit point.
    pub p: Vec3,
    /// Unit geometric normal, facing the ray's origin.
    pub ng: Vec3,
    /// Unit shading normal (interpolated vertex normals where the scene has them, else
    /// `ng`), on the same side as `ng`.
    pub ns: Vec3,
    /// Whether the ray hit the side the triangle's winding faces (counter-clockwise front),
    /// i.e. it enters a closed, outward-wound mesh.
    pub front: bool,
    /// Unit direction back toward the ray's origin.
    pub wo: Vec3,
}

impl SurfaceHit {
    /// Computes the point and normals of `hit` on `ray` (reads the vertex normals of the
    /// hit triangle, if the scene has them).
    pub fn new(scene: &Scene, ray: &Ray, hit: Hit) -> SurfaceHit {
        let raw = hit.geometric_normal().normalize_or_zero();
        let front = raw.dot(ray.dir) < 0.0;
        let ng = if front { raw } else { -raw };
        let mut ns = ng;
        if let Some(n) = scene.normals(hit.part, hit.prim) {
            let w = 1.0 - hit.u - hit.v;
            let mut n = Vec3::from(n[0]) * w + Vec3::from(n[1]) * hit.u + Vec3::from(n[2]) * hit.v;
            if let Some(p) = &hit.placed {
                n = p.normal_to_world(n);
            }
            let n = n.normalize_or_zero();
            if n != Vec3::ZERO {
                ns = if n.dot(ng) < 0.0 { -n } else { n };
            }
        }
        SurfaceHit { p: ray.org + ray.dir * hit.t, ng, ns, front, wo: -ray.dir.normalize_or_zero(), hit }
    }
}

/// What a shader may use: rays, the world's lights and settings, random numbers.
pub struct ShadeCtx<'a> {
    world: &'a World,
    /// The shader that shades the hits of [`ShadeCtx::trace`].
    shader: &'a dyn Shader,
    /// The footprint of the rays this context fires next, and the surface they leave
    /// ([`ShadeCtx::enter`]): what a tracer with levels of detail chooses them by.
    cone: RayCone,
    caster: &'a mut dyn RayCaster,
    sampler: Sampler,
    subset: u32,
    depth: u32,
    rays: u32,
    /// The density (per solid angle) of the diffuse or glossy bounce that reached the
    /// current hit, `None` for a camera ray or a specular bounce ([`ShadeCtx::emitted`]).
    bounce_pdf: Option<f32>,
}

/// A path's diffuse or glossy bounce ([`ShadeCtx::trace_bounce`]): how what it reaches is
/// weighed against next-event estimation of the same light.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Bounce {
    /// The weight of the environment where the bounce escapes.
    pub env_weight: f32,
    /// The density (per solid angle) with which the direction was drawn.
    pub pdf: f32,
}

impl<'a> ShadeCtx<'a> {
    /// A context for one sample in `world`, whose further hits `shader` shades: `subset` is
    /// its light subset (interleaved sampling).
    pub fn new(
        world: &'a World,
        shader: &'a dyn Shader,
        caster: &'a mut dyn RayCaster,
        sampler: Sampler,
        subset: u32,
    ) -> Self {
        let cone = RayCone::camera(world.settings.camera.pixel_angle());
        ShadeCtx { world, shader, caster, sampler, subset, cone, depth: 0, rays: 0, bounce_pdf: None }
    }

    /// The footprint of the rays fired next ([`RayCaster::intersect_cone`]).
    pub fn cone(&self) -> RayCone {
        self.cone
    }

    /// Makes the rays fired next leave `hit`'s surface, `hit.t` along a ray of the current
    /// footprint: they start as wide as that ray was there and widen twice as fast (a bounce
    /// spreads them), and keep to the level of detail of the surface's part or coarser.
    /// Returns the footprint before, to give back to [`ShadeCtx::leave`].
    pub fn enter(&mut self, hit: &Hit) -> RayCone {
        let before = self.cone;
        let c = before.cone;
        self.cone = RayCone { cone: Cone { width: c.at(hit.t), spread: 2.0 * c.spread }, from_part: Some(hit.part) };
        before
    }

    /// Restores the footprint [`ShadeCtx::enter`] returned.
    pub fn leave(&mut self, before: RayCone) {
        self.cone = before;
    }

    /// The world (settings, environment, scale).
    pub fn world(&self) -> &'a World {
        self.world
    }

    /// The settings (the world's).
    pub fn settings(&self) -> &'a RenderSettings {
        &self.world.settings
    }

    /// The scene the rays are traced in.
    pub fn scene(&self) -> &Scene {
        self.caster.scene()
    }

    /// The closest hit of `ray` (its footprint this context's [`ShadeCtx::cone`]).
    pub fn intersect(&mut self, ray: &Ray) -> Result<Option<Hit>, Suspended> {
        self.rays += 1;
        self.caster.intersect_cone(ray, &self.cone)
    }

    /// Counts the camera ray, traced before this context was made
    /// ([`crate::Renderer::sample`]), among its rays.
    pub(crate) fn count_camera_ray(&mut self) {
        self.rays += 1;
    }

    /// Whether anything lies on `ray` (any hit, for shadows).
    pub fn occluded(&mut self, ray: &Ray) -> Result<bool, Suspended> {
        self.rays += 1;
        self.caster.occluded_cone(ray, &self.cone)
    }

    /// Rays fired so far.
    pub fn rays(&self) -> u32 {
        self.rays
    }

    /// How many shaders deep this context is (0 at the camera ray's hit).
    pub fn depth(&self) -> u32 {
        self.depth
    }

    /// The radiance arriving along `ray`: its closest hit shaded by the sample's shader, or
    /// the environment where it misses. Beyond `max_depth` nested calls it returns black.
    pub fn trace(&mut self, ray: &Ray) -> Result<Vec3, Suspended> {
        self.trace_bounce(ray, None)
    }

    /// [`ShadeCtx::trace`] for a path's bounce. Where it misses: with `bounce` `None`, the
    /// environment as the camera sees it (a specular bounce, which no shadow ray can stand
    /// for); with `Some(b)`, the environment's pixel in that direction ([`ShadeCtx::environment_pixel`],
    /// the radiance light sampling integrates) times `b.env_weight`, the bounce's weight in
    /// multiple importance sampling against next-event estimation of the same light. An area
    /// light it hits is weighed by `b.pdf` ([`ShadeCtx::emitted`]).
    pub fn trace_bounce(&mut self, ray: &Ray, bounce: Option<Bounce>) -> Result<Vec3, Suspended> {
        if self.depth >= self.world.settings.max_depth {
            return Ok(Vec3::ZERO);
        }
        let Some(hit) = self.intersect(ray)? else {
            return Ok(match bounce {
                None => self.background(ray.dir),
                Some(b) if b.env_weight > 0.0 => self.environment_pixel(ray.dir) * b.env_weight,
                Some(_) => Vec3::ZERO,
            });
        };
        let sh = SurfaceHit::new(self.scene(), ray, hit);
        let shader = self.shader;
        self.depth += 1;
        let before = self.enter(&hit);
        let pdf_before = std::mem::replace(&mut self.bounce_pdf, bounce.map(|b| b.pdf));
        let c = shader.shade(ray, &sh, self);
        self.bounce_pdf = pdf_before;
        self.leave(before);
        self.depth -= 1;
        c
    }

    /// The radiance `hit`'s surface emits toward the ray's origin if it is an area light
    /// (0 if not, or if the ray sees its back). Reached by a path's diffuse or glossy bounce,
    /// it is weighed against next-event estimation of the same light, which drew
    /// `light_samples` points on the lights (the power heuristic).
    pub fn emitted(&self, hit: &SurfaceHit) -> Vec3 {
        let Some(area) = self.world.area_lights() else { return Vec3::ZERO };
        let scene = self.scene();
        let over = hit.hit.placed.and_then(|p| p.material());
        let Some((l, two_sided)) =
            over.or_else(|| scene.material_index(hit.hit.part, hit.hit.prim)).and_then(|m| area.emission(m))
        else {
            return Vec3::ZERO;
        };
        if !hit.front && !two_sided {
            return Vec3::ZERO;
        }
        match self.bounce_pdf {
            None => l,
            Some(pb) => {
                let k = self.world.settings.light_samples.max(1) as f32;
                let pl = k * area.pdf(l, two_sided, hit.hit.t, hit.ng.dot(hit.wo));
                l * (pb * pb / (pb * pb + pl * pl))
            }
        }
    }

    /// The radiance of the environment's pixel in direction `dir` (constant over the pixel:
    /// what [`crate::EnvSampler`] samples; the camera sees the map interpolated, and light
    /// sampling of an interpolated sun would put its edge into dim pixels of low density).
    pub fn environment_pixel(&self, dir: Vec3) -> Vec3 {
        if self.world.has_environment() {
            self.world.environment().map.eval_pixel(dir.normalize_or_zero())
        } else {
            self.background(dir)
        }
    }

    /// What a ray leaving in direction `dir` sees when it hits nothing.
    pub fn background(&self, dir: Vec3) -> Vec3 {
        self.world.background(dir)
    }

    /// The surface's material (reads its attributes now).
    pub fn material(&self, hit: &SurfaceHit) -> Material {
        material_at(self.scene(), &hit.hit, self.world.textures())
    }

    /// A ray from `hit` in direction `dir`, its origin moved off the surface to the side
    /// `dir` leaves on: by the world's epsilon, plus the error of the surface's level of
    /// detail (a stand-in lies within it of the surface it stands for, which must not
    /// shadow it).
    pub fn spawn(&self, hit: &SurfaceHit, dir: Vec3) -> Ray {
        let side = if dir.dot(hit.ng) >= 0.0 { hit.ng } else { -hit.ng };
        let lod = self.scene().parts().get(hit.hit.part as usize).map_or(0.0, |p| p.lod_error);
        Ray { org: hit.p + side * (self.world.eps() + lod), dir, t_min: 0.0, t_max: f32::INFINITY }
    }

    /// The next random number of this sample, in `[0, 1)`.
    pub fn next_1d(&mut self) -> f32 {
        self.sampler.next_1d()
    }

    /// The next pair of random numbers of this sample.
    pub fn next_2d(&mut self) -> (f32, f32) {
        self.sampler.next_2d()
    }

    /// Irradiance that reaches every point regardless of shadows: `pi * ambient` when the
    /// world lights with its single directional light, 0 under an environment.
    pub fn ambient(&self) -> f32 {
        if self.world.has_environment() {
            0.0
        } else {
            std::f32::consts::PI * self.world.settings.ambient
        }
    }

    /// Direct light at `hit` from the world's lights, with shadows:
    /// `sum over chosen lights of weight * brdf(light dir) * cos * visible`, an unbiased
    /// estimate of the reflected radiance for the BRDF `brdf` (1/sr; `albedo / pi` for a
    /// Lambertian surface).
    ///
    /// The lights are the environment's virtual lights when the world has one (see
    /// [`ShadeCtx::env_direct`]), else the single directional light `settings.light` with
    /// irradiance `pi * (1 - ambient)` (so that a white surface facing it shows
    /// `1 - ambient`, plus the ambient term).
    pub fn direct(&mut self, hit: &SurfaceHit, brdf: impl Fn(Vec3) -> Vec3) -> Result<Vec3, Suspended> {
        if self.world.has_environment() {
            return self.env_direct(hit, brdf);
        }
        let s = &self.world.settings;
        let light =
            DirLight { dir: s.light.normalize(), weight: Vec3::splat(std::f32::consts::PI * (1.0 - s.ambient)) };
        self.light_contribution(hit, &light, 1.0, &brdf)
    }

    /// Direct light from the environment's virtual lights (the given environment, or the
    /// constant sky colour), with interleaved sampling: this sample's subset, weights times
    /// the number of subsets, and `light_samples` of the subset's lights drawn as
    /// `settings.light_select` says ([`crate::LightSelect`]; stratified, each weighted by one
    /// over its probability), or every light of the subset when `light_samples` is 0 or at
    /// least the subset's size.
    pub fn env_direct(&mut self, hit: &SurfaceHit, brdf: impl Fn(Vec3) -> Vec3) -> Result<Vec3, Suspended> {
        let lights = &self.world.environment().lights;
        let m = lights.subsets() as f32;
        let subset = lights.subset(self.subset);
        let n = subset.len();
        if n == 0 {
            return Ok(Vec3::ZERO);
        }
        let k = self.world.settings.light_samples as usize;
        let mut sum = Vec3::ZERO;
        if k == 0 || k >= n {
            for l in subset {
                sum += self.light_contribution(hit, l, m, &brdf)?;
            }
            return Ok(sum);
        }
        let u = self.next_1d();
        if self.world.settings.light_select == crate::LightSelect::Uniform {
            let scale = m * n as f32 / k as f32;
            for j in 0..k {
                let i = (((j as f32 + u) / k as f32 * n as f32) as usize).min(n - 1);
                sum += self.light_contribution(hit, &subset[i], scale, &brdf)?;
            }
            return Ok(sum);
        }
        // Power times cosine; 0 below the horizon of either normal (such a light brings
        // nothing: see light_contribution).
        let mut stack = [0.0f32; 128];
        let mut heap = Vec::new();
        let w: &mut [f32] = if n <= stack.len() {
            &mut stack[..n]
        } else {
            heap.resize(n, 0.0);
            &mut heap
        };
        for (w, l) in w.iter_mut().zip(subset) {
            let cos = hit.ns.dot(l.dir);
            *w = if cos > 0.0 && hit.ng.dot(l.dir) > 0.0 { crate::luminance(l.weight) * cos } else { 0.0 };
        }
        for (i, f) in crate::Draws::new(w, k, u) {
            sum += self.light_contribution(hit, &subset[i], m * f, &brdf)?;
        }
        Ok(sum)
    }

    fn light_contribution(
        &mut self,
        hit: &SurfaceHit,
        l: &DirLight,
        scale: f32,
        brdf: &impl Fn(Vec3) -> Vec3,
    ) -> Result<Vec3, Suspended> {
        let cos = hit.ns.dot(l.dir);
        if cos <= 0.0 || hit.ng.dot(l.dir) <= 0.0 {
            return Ok(Vec3::ZERO);
        }
        let f = brdf(l.dir);
        if f == Vec3::ZERO {
            return Ok(Vec3::ZERO);
        }
        if self.occluded(&self.spawn(hit, l.dir))? {
            return Ok(Vec3::ZERO);
        }
        Ok(l.weight * f * (cos * scale))
    }
}
