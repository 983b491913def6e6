//! What `render`, `view` and `serve` open: a scene file as it is; a model file (PLY, OBJ,
//! STL, glTF/GLB) built out of core into a scene cached under `~/.cache/megaray/models`,
//! keyed by the model's content and reused next time (`--no-cache`: built into a temporary
//! folder, removed at exit); with no path (the viewers), the demo's plant.

use std::io::Read;
use std::path::{Path, PathBuf};

use anyhow::{Context, Result};
use clap::Args;
use megaray_base::{parse_size, Progress};
use megaray_scene::{Scene, SceneErrorKind};

/// The options of commands that open models as well as scenes.
#[derive(Args, Clone, Debug, Default)]
pub struct OpenArgs {
    /// A model file given instead of a scene is built into a temporary scene (removed at
    /// exit) rather than into the cache under ~/.cache/megaray/models.
    #[arg(long)]
    pub no_cache: bool,
    /// Memory budget of that build (see `megaray build --build-mem`).
    #[arg(long, value_name = "SIZE", default_value = "2G", value_parser = |s: &str| parse_size(s).map_err(|e| e.to_string()))]
    pub build_mem: u64,
}

/// A scene file to open, and the temporary folder that holds it when it was built for this
/// run only.
pub struct Opened {
    pub path: PathBuf,
    _tmp: Option<tempfile::TempDir>,
}

/// The scene for `path` (see the module documentation).
pub fn scene_for(path: Option<&Path>, o: &OpenArgs, bars: &dyn Progress) -> Result<Opened> {
    let Some(path) = path else {
        let dir = crate::cmd::cache_dir(None);
        return Ok(Opened { path: crate::cmd::demo_scene(&dir, "3M", 192 << 20, bars)?, _tmp: None });
    };
    // The tables only: a compact file is not decoded here.
    match Scene::open_owned(path) {
        Ok(_) => return Ok(Opened { path: path.to_path_buf(), _tmp: None }),
        Err(e)
            if e.kind != SceneErrorKind::NotAScene
                || (megaray_import::Format::detect(path).is_err() && !is_pbrt(path)) =>
        {
            return Err(e.into())
        }
        Err(_) => {}
    }
    // A model: built into the cache (or a temporary folder).
    let stem = path.file_stem().map(|s| s.to_string_lossy().into_owned()).unwrap_or_default();
    let (dir, tmp) = if o.no_cache {
        let t = tempfile::tempdir().context("cannot make a temporary folder")?;
        (t.path().to_path_buf(), Some(t))
    } else {
        (crate::cmd::cache_dir(None).join("models"), None)
    };
    std::fs::create_dir_all(&dir).with_context(|| format!("{}: cannot create the folder", dir.display()))?;
    let key = content_key(path)?;
    let out = dir.join(format!("{}-{key:016x}.mray", sanitize(&stem)));
    if Scene::open_owned(&out).is_ok() {
        eprintln!("{}: the scene built from it before: {}", path.display(), out.display());
    } else {
        eprintln!("{}: building it into {}", path.display(), out.display());
        crate::cmd::build_into(vec![path.to_path_buf()], &out, o.build_mem, bars)?;
    }
    Ok(Opened { path: out, _tmp: tmp })
}

/// A key for a model's content: XXH3-64 of its bytes and length, and the scene format
/// version (a new format builds it anew). Files a model names are not read: a changed `.bin`
/// beside an unchanged `.gltf`, or a PLY or include of a `.pbrt` scene, is not seen (the cache
/// can be cleared).
fn content_key(path: &Path) -> Result<u64> {
    let mut f = std::fs::File::open(path).with_context(|| format!("{}: cannot open", path.display()))?;
    let mut h = xxhash_rust::xxh3::Xxh3::new();
    let mut buf = vec![0u8; 1 << 20];
    let mut len = 0u64;
    loop {
        let n = f.read(&mut buf).with_context(|| format!("{}: cannot read", path.display()))?;
        if n == 0 {
            break;
        }
        h.update(&buf[..n]);
        len += n as u64;
    }
    h.update(&len.to_le_bytes());
    h.update(&megaray_scene::format::VERSION.to_le_bytes());
    Ok(h.digest())
}

/// `name` with anything but letters, digits, `-` and `_` made `_` (a file name of our own).
fn sanitize(name: &str) -> String {
    let s: String =
        name.chars().map(|c| if c.is_ascii_alphanumeric() || c == '-' || c == '_' { c } else { '_' }).collect();
    if s.is_empty() {
        "model".into()
    } else {
        s
    }
}

/// The scene among `inputs` whose structure the build keeps (objects and instances), parsed,
/// what it skipped noted one line per kind: a pbrt-v4 scene (which must be the only input),
/// or a glTF file given alone (several inputs are merged, flattened, as other models).
pub(crate) fn structured_scene(
    inputs: &[PathBuf],
    bars: &dyn Progress,
) -> Result<Option<megaray_import::pbrt::PbrtScene>> {
    let is_gltf = |p: &PathBuf| {
        let n = p.to_string_lossy().to_ascii_lowercase();
        n.ends_with(".gltf") || n.ends_with(".glb")
    };
    let scene = match inputs {
        [p] if is_gltf(p) => (p, megaray_import::gltf_scene::read_scene(p)?),
        _ => match inputs.iter().find(|p| is_pbrt(p)) {
            None => return Ok(None),
            Some(p) if inputs.len() > 1 => {
                anyhow::bail!("{}: a pbrt scene is built on its own (give it as the only input)", p.display())
            }
            Some(p) => (p, megaray_import::pbrt::read_scene(p)?),
        },
    };
    note(scene.0, &scene.1, bars);
    Ok(Some(scene.1))
}

/// Whether `p` names a pbrt-v4 scene (`.pbrt`, `.pbrt.gz`).
fn is_pbrt(p: &Path) -> bool {
    let n = p.to_string_lossy().to_ascii_lowercase();
    n.ends_with(".pbrt") || n.ends_with(".pbrt.gz")
}

/// One note line per kind of thing a scene's reader skipped.
fn note(p: &Path, scene: &megaray_import::pbrt::PbrtScene, bars: &dyn Progress) {
    for (what, n) in &scene.skipped {
        // A kind that says what became of it carries its own words.
        let why = if what.ends_with(')') { "" } else { " (not drawn by megaray)" };
        bars.note(&format!("{}: skipped {n} x {what}{why}", p.display()));
    }
}

/// The scene file's settings (its source's camera and lights), parsed.
fn settings(scene: &megaray_scene::Scene) -> Option<serde_json::Value> {
    serde_json::from_str(scene.settings()?).ok()
}

/// A `[x, y, z]` of the settings.
fn vec3(v: &serde_json::Value) -> Option<megaray_base::Vec3> {
    let c = |i: usize| v.get(i).and_then(|x| x.as_f64()).map(|x| x as f32);
    Some(megaray_base::Vec3::new(c(0)?, c(1)?, c(2)?))
}

/// The camera the scene file's source gave (a pbrt scene's), at `w` x `h`; its field of
/// view (pbrt's, of the shorter side) made vertical.
pub(crate) fn scene_camera(scene: &megaray_scene::Scene, w: u32, h: u32) -> Option<megaray_base::Camera> {
    let v = settings(scene)?;
    let c = v.get("camera")?;
    let fov = c.get("fov")?.as_f64()? as f32;
    let vfov =
        if w < h { 2.0 * ((fov.to_radians() / 2.0).tan() * h as f32 / w as f32).atan().to_degrees() } else { fov };
    Some(megaray_base::Camera::look_at(vec3(c.get("eye")?)?, vec3(c.get("at")?)?, vec3(c.get("up")?)?, vfov, w, h))
}

/// The area lights the scene's source gave (a pbrt scene's `AreaLightSource`), if any; an
/// error names the scene file and what is wrong with its list.
pub(crate) fn scene_area_lights(
    scene: &megaray_scene::Scene,
) -> anyhow::Result<Option<std::sync::Arc<megaray_render::AreaLights>>> {
    let Some(list) = settings(scene).and_then(|v| v.get("area_lights").cloned()) else { return Ok(None) };
    let bad =
        |i: usize, what: &str| anyhow::anyhow!("{}: area light {i} of the settings: {what}", scene.path().display());
    let list = list.as_array().ok_or_else(|| bad(0, "not a list"))?;
    let mut lights = Vec::with_capacity(list.len());
    let mut count = 0usize;
    for (i, l) in list.iter().enumerate() {
        let material = l.get("material").and_then(|m| m.as_u64()).ok_or_else(|| bad(i, "no material"))?;
        if material >= scene.materials().len() as u64 {
            return Err(bad(i, &format!("material {material} is not in the table ({})", scene.materials().len())));
        }
        let radiance = l.get("radiance").and_then(vec3).ok_or_else(|| bad(i, "no radiance"))?;
        let two_sided = l.get("two_sided").and_then(|b| b.as_bool()).unwrap_or(false);
        let tris = l.get("triangles").and_then(|t| t.as_array()).ok_or_else(|| bad(i, "no triangles"))?;
        count += tris.len();
        if count > megaray_import::pbrt::MAX_AREA_TRIANGLES {
            return Err(bad(i, "more area-light triangles than megaray samples"));
        }
        let mut triangles = Vec::with_capacity(tris.len());
        for t in tris {
            let v: Vec<f32> = t
                .as_array()
                .map(|a| a.iter().filter_map(|x| x.as_f64()).map(|x| x as f32).collect())
                .unwrap_or_default();
            if v.len() != 9 {
                return Err(bad(i, "a triangle that is not 9 numbers"));
            }
            let c = |k: usize| megaray_base::Vec3::new(v[3 * k], v[3 * k + 1], v[3 * k + 2]);
            triangles.push([c(0), c(1), c(2)]);
        }
        lights.push(megaray_render::AreaLight { material: material as u32, radiance, two_sided, triangles });
    }
    let area = megaray_render::AreaLights::new(&lights);
    Ok((!area.is_empty()).then(|| std::sync::Arc::new(area)))
}

/// The environment map (file, scale) and the sun's direction the scene's source gave.
pub(crate) fn scene_lights(scene: &megaray_scene::Scene) -> (Option<(PathBuf, f32)>, Option<megaray_base::Vec3>) {
    let Some(v) = settings(scene) else { return (None, None) };
    let env = v.get("environment").and_then(|e| {
        let file = PathBuf::from(e.get("file")?.as_str()?);
        Some((file, e.get("scale").and_then(|s| s.as_f64()).unwrap_or(1.0) as f32))
    });
    let sun = v.get("sun").and_then(|s| vec3(s.get("dir")?)).filter(|d| d.length() > 0.0);
    (env, sun)
}
