//! # megaray-render: images from a scene
//!
//! The render crate turns rays into pictures. Its parts, one concept a module:
//!
//! - [`Camera`] (from `megaray-base`, re-exported): pinhole camera, the benchmark framings.
//! - [`RenderSettings`], [`Builtin`] (`settings.rs`): how to render, plain data; `World`
//!   (`world.rs`): what a shader sees of the renderer. Imports run one way:
//!   `frame` -> `shader` -> `world` -> `settings`.
//! - [`Shader`], [`ShadeCtx`], [`SurfaceHit`] (`shader.rs`): the interface called at each
//!   hit; shaders fire arbitrary rays through [`megaray_trace::RayCaster`] (closest hit, any
//!   hit, or recursively shaded). [`Builtin`] (`shaders/`): `normal`, `diffuse`, `phong`,
//!   `mirror`, `glass`, `ao`, `env`, `auto`. Your own shader is a type implementing
//!   [`Shader`], passed to [`Renderer::with_shader`] (see `examples/custom_shader.rs`).
//! - [`Material`] (`material.rs`): vertex colours, material parameters and textures, read
//!   from the scene's attribute arrays only for the hits whose shader asks.
//! - [`AreaLights`] (`area.rs`): emitting triangles (a pbrt scene's area lights), shown by
//!   every shader and sampled as lights by `path`.
//! - [`EnvMap`], [`EnvLights`], [`Environment`] (`env.rs`): HDR environment maps (.hdr,
//!   .exr, lat-long) turned into N importance-sampled virtual directional lights, split into
//!   M subsets for interleaved sampling.
//! - [`SkySpec`] (`sky.rs`): a procedural sky and sun, written as .hdr for tests and demos.
//! - `sampling.rs`: the per-pixel low-discrepancy sequences ([`Sampler`]) and the
//!   interleaved light-subset pattern ([`light_subset`]).
//! - [`Renderer`], [`render_frame`] (`frame.rs`): one sample as a function
//!   ([`Renderer::sample`]), and the frame loop over 32x32 tiles on rayon's threads.
//! - [`Accumulator`], [`render_progressive`] (`accum.rs`): progressive accumulation of frames
//!   with an error estimate.
//! - [`Visibility`], [`Filtered`] (`visibility.rs`): hidden and X-rayed components,
//!   section planes with caps, applied to every ray by a caster that steps past what is
//!   not shown.
//! - [`Image`], [`ToneMap`], [`save_exr`] (`image_out.rs`): tone-mapped PNG, float OpenEXR
//!   with depth, normal and albedo layers.
//!
//! [`render`] is the one-call form: one frame, the settings' built-in shader.
//!
//! ```no_run
//! use megaray_scene::Scene;
//! use megaray_trace::Tracer;
//! use megaray_render::{render, Camera, RenderSettings, DEFAULT_OFFSET};
//! let scene = Scene::open("model.mray".as_ref()).unwrap();
//! let cam = Camera::framing(&scene.header().bounds, DEFAULT_OFFSET, 1024, 768);
//! let img = render(&Tracer::new(&scene), &RenderSettings::new(cam));
//! img.save_png("out.png".as_ref()).unwrap();
//! ```
//!
//! Progressive rendering under a sky:
//!
//! ```no_run
//! use std::sync::Arc;
//! use megaray_scene::Scene;
//! use megaray_trace::Tracer;
//! use megaray_render::*;
//! let scene = Scene::open("model.mray".as_ref()).unwrap();
//! let mut s = RenderSettings::new(Camera::framing(&scene.header().bounds, DEFAULT_OFFSET, 640, 480));
//! s.shader = Builtin::Env;
//! let env = Environment::new(SkySpec::default().map(), 1024, 16);
//! let r = Renderer::new(s, &scene.header().bounds).with_environment(Arc::new(env));
//! let stop = Stop { frames: Some(16), time: None };
//! let acc = render_progressive(&r, &Tracer::new(&scene), stop, |a| eprintln!("{} frames", a.frames()));
//! acc.image().save_png("out.png".as_ref()).unwrap();
//! ```

#![warn(missing_docs)]

mod accum;
mod adaptive;
mod area;
mod denoise;
mod env;
mod env_sample;
mod frame;
mod governor;
mod image_out;
mod lights;
mod material;
mod region;
mod rows;
mod sampling;
mod settings;
mod shader;
pub mod shaders;
mod sky;
mod tiled;
mod visibility;
mod world;

pub use accum::{render_progressive, render_progressive_with, Accumulator, Stop};
pub use area::{AreaLight, AreaLights, LightSample};
pub use denoise::{denoise, DenoiseInput, PASSES as DENOISE_PASSES};
pub use env::{dir_from_angles, luminance, DirLight, EnvError, EnvLights, EnvMap, Environment};
pub use env_sample::EnvSampler;
pub use frame::{render_frame, render_frame_with, Frame, FrameOptions, Renderer, SampleOut, TILE};
pub use governor::LodGovernor;
pub use image_out::{read_exr, save_exr, srgb, srgb_by_table, Aovs, Image, ImageError, ToneCurve, ToneMap};
pub use lights::{Draws, LightSelect};
pub use material::{Material, DEFAULT_ALBEDO};
pub use megaray_base::{Camera, CLOSE_OFFSET, DEFAULT_OFFSET};
pub use region::{render_pieces, Piece, Rect};
pub use sampling::{light_subset, pixel_offset, Sampler};
pub use settings::{default_light, Builtin, RenderSettings};
pub use shader::{Bounce, ShadeCtx, Shader, SurfaceHit};
pub use sky::{write_env, SkySpec};
pub use visibility::{Filtered, Section, Visibility, CAP_COLOR};
pub use world::World;

use megaray_trace::Tracer;

/// Renders one image: frame 0 of `settings` with its built-in shader, lit by the
/// directional light (no environment). Uses the current rayon pool (install one to choose
/// the thread count).
pub fn render(tracer: &Tracer, settings: &RenderSettings) -> Image {
    let r = Renderer::new(settings.clone(), &tracer.scene().header().bounds);
    render_frame(&r, tracer, 0).image
}
