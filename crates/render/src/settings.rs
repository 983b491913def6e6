//! How to render ([`RenderSettings`]) and which built-in shader ([`Builtin`]): plain data, read
//! by the renderer, the shaders and the front ends.

use std::time::Duration;

use megaray_base::{Camera, Vec3};

/// The direction toward the benchmark light, normalize(0.5, 1, 0.8).
pub fn default_light() -> Vec3 {
    Vec3::new(0.5, 1.0, 0.8).normalize()
}

/// How to render.
#[derive(Clone, Debug)]
pub struct RenderSettings {
    /// The camera (and the image size).
    pub camera: Camera,
    /// Direction toward the directional light (normalised where used). It lights the
    /// `diffuse` and `phong` shaders when there is no environment.
    pub light: Vec3,
    /// Samples per pixel per frame: sample `i` of a pixel sits at [`pixel_offset`](crate::pixel_offset)`(i)`, so 1
    /// sample is the pixel centre in the first frame.
    pub spp: u32,
    /// Adaptive sampling in progressive runs ([`crate::render_progressive`]): from the
    /// second frame on, pixels where the picture changes sharply take this many samples a
    /// frame (at most 255; 0 or 1: off).
    pub adaptive: u32,
    /// Radiance of the sky where rays miss, when there is no environment map; also the
    /// constant environment of the `env` shader then.
    pub sky: [f32; 3],
    /// Light reaching surfaces that the directional light does not (a constant ambient
    /// term; not used under an environment).
    pub ambient: f32,
    /// Offset of secondary-ray origins along the normal, as a fraction of the scene diagonal.
    pub eps_scale: f32,
    /// The built-in shader (a custom one is set with [`Renderer::with_shader`](crate::Renderer::with_shader)).
    pub shader: Builtin,
    /// Shadow rays per hit toward the environment's lights (0: every light of the subset);
    /// rays per hit for ambient occlusion.
    pub light_samples: u32,
    /// How those shadow rays' lights are drawn from the sample's subset: in proportion to
    /// power times cosine (the default) or uniformly (the seed tutorial's way).
    pub light_select: crate::LightSelect,
    /// Nesting limit of [`ShadeCtx::trace`](crate::ShadeCtx::trace) (mirror and glass bounces).
    pub max_depth: u32,
    /// Ambient occlusion distance, as a fraction of the scene diagonal.
    pub ao_radius: f32,
    /// Whether samples compute the AOVs (depth, normal, albedo).
    pub aovs: bool,
    /// End each frame after this long even if pixels are left (out-of-core rendering: the
    /// pixels that wait for tiles are flagged in [`Frame::done`](crate::Frame::done) and left to later frames).
    pub frame_deadline: Option<Duration>,
    /// Where a ray needs a tile that is not resident, answer it from a coarser level of
    /// detail that is (the tile is requested; later frames refine the pixel) instead of
    /// waiting ([`crate::FrameOptions::stand_in`]). Meant with a deadline, and for viewers.
    pub stand_in: bool,
    /// A component ([`megaray_scene::Components`]) whose surfaces camera rays show tinted
    /// (the viewer's picked part).
    pub highlight: Option<u32>,
    /// Hidden and X-rayed components and section planes ([`crate::Visibility`]); `None`
    /// shows everything.
    pub visibility: Option<std::sync::Arc<crate::Visibility>>,
}

impl RenderSettings {
    /// The defaults for `camera`: the benchmark light, 1 sample per pixel, the `diffuse`
    /// shader, 2 light samples, depth limit 6, no AOVs.
    pub fn new(camera: Camera) -> RenderSettings {
        RenderSettings {
            camera,
            light: default_light(),
            spp: 1,
            adaptive: 0,
            sky: [0.55, 0.7, 0.9],
            ambient: 0.12,
            eps_scale: 1e-4,
            shader: Builtin::Diffuse,
            light_samples: 2,
            light_select: crate::LightSelect::Contribution,
            max_depth: 6,
            ao_radius: 0.05,
            aovs: false,
            frame_deadline: None,
            stand_in: false,
            highlight: None,
            visibility: None,
        }
    }
}

/// The built-in shaders. A closed set: one `match` per hit.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub enum Builtin {
    /// The shading normal as a colour, `n * 0.5 + 0.5`.
    Normal,
    /// Lambertian under the lights, with shadows (plus the ambient term under the single
    /// directional light). The default, and what `render` always did.
    #[default]
    Diffuse,
    /// Lambertian plus Blinn-Phong highlights (material `Ks`, `Ns`; 0.3 and 32 when absent).
    Phong,
    /// A perfect mirror (reflectance 0.9), recursive up to the depth limit.
    Mirror,
    /// Clear glass of index 1.5: Fresnel (Schlick) reflection or refraction, one of the two
    /// chosen at random in proportion, recursive up to the depth limit.
    Glass,
    /// Ambient occlusion: albedo times the fraction of `light_samples` cosine-distributed
    /// rays that travel `ao_radius` (a fraction of the scene diagonal) unblocked.
    Ao,
    /// Lambertian under the environment light (the `--env` map, or the constant sky colour),
    /// with shadows, by interleaved sampling of its virtual lights.
    Env,
    /// By material: opacity below 1 is glass, metallic at least 0.5 is a mirror tinted by the
    /// base colour, a specular colour with a shininess is Phong, anything else diffuse (under
    /// the environment when there is one).
    Auto,
    /// Global illumination: paths of diffuse, glossy, mirror and glass bounces (materials as
    /// `auto` reads them) with next-event estimation of the environment's virtual lights at
    /// every surface, Russian roulette and the depth limit (`shaders::path`).
    Path,
}

impl Builtin {
    /// Every built-in, with its name.
    pub const ALL: [(&'static str, Builtin); 9] = [
        ("normal", Builtin::Normal),
        ("diffuse", Builtin::Diffuse),
        ("phong", Builtin::Phong),
        ("mirror", Builtin::Mirror),
        ("glass", Builtin::Glass),
        ("ao", Builtin::Ao),
        ("env", Builtin::Env),
        ("auto", Builtin::Auto),
        ("path", Builtin::Path),
    ];

    /// The name `--shader` takes.
    pub fn name(self) -> &'static str {
        Builtin::ALL.iter().find(|(_, b)| *b == self).map(|(n, _)| *n).unwrap_or("?")
    }
}

impl std::str::FromStr for Builtin {
    type Err = String;
    fn from_str(s: &str) -> Result<Builtin, String> {
        Builtin::ALL.iter().find(|(n, _)| *n == s).map(|(_, b)| *b).ok_or_else(|| {
            let names: Vec<&str> = Builtin::ALL.iter().map(|(n, _)| *n).collect();
            format!("unknown shader `{s}` (known: {})", names.join(", "))
        })
    }
}
