//! Surface attributes at a hit, read from the scene's attribute arrays only when a shader
//! asks for them (traversal never touches them): material parameters, vertex colours,
//! texture colour.

use std::collections::HashMap;
use std::sync::{Arc, RwLock};

use megaray_base::Vec3;
use megaray_scene::Scene;
use megaray_trace::Hit;

/// The albedo of surfaces that have neither vertex colours nor a material.
pub const DEFAULT_ALBEDO: f32 = 0.8;

/// The shading parameters of a surface point, from its material (OBJ .mtl `Kd Ks Ns d`,
/// glTF base colour, metallic, roughness, base colour texture) and vertex colours.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Material {
    /// Diffuse colour: vertex colour, else material diffuse times texture, else 0.8 grey.
    pub albedo: Vec3,
    /// Specular colour (OBJ `Ks`); zero when the material has none.
    pub specular: Vec3,
    /// Phong exponent (OBJ `Ns`); 0 when the material has none.
    pub shininess: f32,
    /// Opacity (OBJ `d`, glTF base colour alpha): below 1 is treated as glass by `auto`.
    pub opacity: f32,
    /// glTF metallic factor (0 when absent).
    pub metallic: f32,
    /// glTF roughness factor (1 when absent).
    pub roughness: f32,
    /// Whether the triangle has a material at all.
    pub has_material: bool,
}

impl Default for Material {
    fn default() -> Material {
        Material {
            albedo: Vec3::splat(DEFAULT_ALBEDO),
            specular: Vec3::ZERO,
            shininess: 0.0,
            opacity: 1.0,
            metallic: 0.0,
            roughness: 1.0,
            has_material: false,
        }
    }
}

/// An RGB texture in linear values (decoded from sRGB), repeat addressing, nearest texel.
pub struct Texture {
    width: u32,
    height: u32,
    texels: Vec<[f32; 3]>,
    /// The mean of the texels: the colour of a surface without texture coordinates (the
    /// levels of detail carry none; far away a texture is seen as its average).
    mean: Vec3,
}

impl Texture {
    /// The colour at texture coordinates (`u`, `v`); `v` = 0 is the bottom row (OBJ and the
    /// importers' convention).
    pub fn sample(&self, u: f32, v: f32) -> Vec3 {
        let x = ((u.rem_euclid(1.0) * self.width as f32) as u32).min(self.width - 1);
        let y = (((1.0 - v.rem_euclid(1.0)) * self.height as f32) as u32).min(self.height - 1);
        Vec3::from(self.texels[(y * self.width + x) as usize])
    }

    /// The mean colour of the texels.
    pub fn mean(&self) -> Vec3 {
        self.mean
    }

    fn new(width: u32, height: u32, texels: Vec<[f32; 3]>) -> Texture {
        let sum = texels.iter().fold([0f64; 3], |a, t| [a[0] + t[0] as f64, a[1] + t[1] as f64, a[2] + t[2] as f64]);
        let n = texels.len().max(1) as f64;
        let mean = Vec3::new((sum[0] / n) as f32, (sum[1] / n) as f32, (sum[2] / n) as f32);
        Texture { width, height, texels, mean }
    }
}

/// Textures loaded on first use, shared by all threads. A texture that cannot be read is
/// remembered as missing (the surface then uses its material colour alone).
#[derive(Default)]
pub struct TextureCache {
    map: RwLock<HashMap<String, Option<Arc<Texture>>>>,
}

impl TextureCache {
    /// The texture at `path`, loaded now if it is the first request.
    pub fn get(&self, path: &str) -> Option<Arc<Texture>> {
        if let Some(t) = self.map.read().unwrap_or_else(|p| p.into_inner()).get(path) {
            return t.clone();
        }
        let tex = image::open(path).ok().map(|img| {
            let img = img.into_rgb8();
            let lin = |c: u8| {
                let c = c as f32 / 255.0;
                if c <= 0.04045 {
                    c / 12.92
                } else {
                    ((c + 0.055) / 1.055).powf(2.4)
                }
            };
            Arc::new(Texture::new(
                img.width().max(1),
                img.height().max(1),
                if img.width() == 0 || img.height() == 0 {
                    vec![[1.0; 3]]
                } else {
                    img.pixels().map(|p| p.0.map(lin)).collect()
                },
            ))
        });
        self.map.write().unwrap_or_else(|p| p.into_inner()).entry(path.to_string()).or_insert(tex).clone()
    }
}

/// The material at `hit` in `scene` (vertex colours, material table, texture).
pub fn material_at(scene: &Scene, hit: &Hit, textures: &TextureCache) -> Material {
    let mut m = Material::default();
    let w = [1.0 - hit.u - hit.v, hit.u, hit.v];
    let over = hit.placed.and_then(|p| p.material()).and_then(|m| scene.materials().get(m as usize));
    if let Some(d) = over.or_else(|| scene.material(hit.part, hit.prim)) {
        m.has_material = true;
        if let Some(c) = d.diffuse {
            m.albedo = Vec3::from(c);
        }
        if let Some(tex) = d.texture.as_deref().and_then(|p| textures.get(p)) {
            match scene.uvs(hit.part, hit.prim) {
                Some(uv) => {
                    let u = uv[0][0] * w[0] + uv[1][0] * w[1] + uv[2][0] * w[2];
                    let v = uv[0][1] * w[0] + uv[1][1] * w[1] + uv[2][1] * w[2];
                    m.albedo *= tex.sample(u, v);
                }
                // A stand-in (levels of detail keep no texture coordinates): the texture's
                // mean, not white.
                None => m.albedo *= tex.mean(),
            }
        }
        m.specular = d.specular.map(Vec3::from).unwrap_or(Vec3::ZERO);
        m.shininess = d.shininess.unwrap_or(0.0);
        m.opacity = d.opacity.unwrap_or(1.0);
        m.metallic = d.metallic.unwrap_or(0.0);
        m.roughness = d.roughness.unwrap_or(1.0);
    }
    if let Some(c) = scene.colors(hit.part, hit.prim) {
        let mut a = [0.0; 3];
        for (k, ak) in a.iter_mut().enumerate() {
            *ak = (0..3).map(|i| c[i][k] as f32 / 255.0 * w[i]).sum();
        }
        m.albedo = Vec3::from(a);
    }
    m
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A surface without texture coordinates (a level of detail) takes the texture's mean.
    #[test]
    fn a_texture_knows_its_mean() {
        let t = Texture::new(2, 1, vec![[0.2, 0.4, 0.0], [0.6, 0.0, 1.0]]);
        assert!((t.mean() - Vec3::new(0.4, 0.2, 0.5)).abs().max_element() < 1e-6);
        assert_eq!(t.sample(0.25, 0.5), Vec3::new(0.2, 0.4, 0.0));
    }
}
