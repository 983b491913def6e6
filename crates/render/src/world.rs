//! What a shader sees of the renderer ([`World`]): the settings, the environment and its
//! lights, the texture cache, and the scene's scale. Below both the shaders and the frame
//! loop, so that neither imports the other.

use std::sync::Arc;

use megaray_base::{Aabb, Vec3};

use crate::area::AreaLights;
use crate::env::Environment;
use crate::material::TextureCache;
use crate::settings::RenderSettings;

/// The settings, environment and textures shared by every sample (and every thread).
pub struct World {
    /// The settings it renders with.
    pub settings: RenderSettings,
    env: Arc<Environment>,
    has_env: bool,
    eps: f32,
    diagonal: f32,
    textures: TextureCache,
    area: Option<Arc<AreaLights>>,
}

impl World {
    /// The world of a scene with bounds `bounds`, lit by the constant sky `settings.sky`
    /// (implicitly: [`World::has_environment`] is false).
    pub fn new(settings: RenderSettings, bounds: &Aabb) -> World {
        let env = Environment::constant(settings.sky, Environment::DEFAULT_LIGHTS, Environment::DEFAULT_SUBSETS);
        let diagonal = bounds.diagonal();
        World {
            eps: settings.eps_scale * diagonal,
            env: Arc::new(env),
            has_env: false,
            diagonal,
            textures: TextureCache::default(),
            area: None,
            settings,
        }
    }

    /// Lit by `env` (what misses see, and the lights of every shader).
    pub(crate) fn set_environment(&mut self, env: Arc<Environment>) {
        self.env = env;
        self.has_env = true;
    }

    /// Adds the scene's area lights.
    pub(crate) fn set_area_lights(&mut self, area: Arc<AreaLights>) {
        self.area = (!area.is_empty()).then_some(area);
    }

    /// The scene's area lights, if it has any ([`crate::Renderer::with_area_lights`]).
    pub fn area_lights(&self) -> Option<&Arc<AreaLights>> {
        self.area.as_ref()
    }

    /// The environment (the constant sky when none was given).
    pub fn environment(&self) -> &Environment {
        &self.env
    }

    /// Whether an environment was given ([`crate::Renderer::with_environment`]).
    pub fn has_environment(&self) -> bool {
        self.has_env
    }

    /// What a ray in direction `dir` sees when it misses everything.
    pub fn background(&self, dir: Vec3) -> Vec3 {
        if self.has_env {
            self.env.map.eval(dir.normalize_or_zero())
        } else {
            Vec3::from(self.settings.sky)
        }
    }

    /// Secondary-ray offset (world units).
    pub fn eps(&self) -> f32 {
        self.eps
    }

    /// Length of the scene's bounding-box diagonal.
    pub fn diagonal(&self) -> f32 {
        self.diagonal
    }

    pub(crate) fn textures(&self) -> &TextureCache {
        &self.textures
    }
}
