//! pbrt-v4 scene files: what megaray renders of them (`docs/INPUT.md`, "pbrt-v4 scenes").
//!
//! [`read_scene`] parses a scene (following `Include` and `Import`) into a [`PbrtScene`]:
//! objects (`ObjectBegin`/`ObjectEnd`, and the world's own shapes as object 0) that keep
//! their shapes unexpanded, and instances (`ObjectInstance`, never flattened) with their
//! transforms; materials mapped to megaray's; the camera and the lights megaray has. The
//! triangles are read later, object by object ([`feed_object`]), so that a scene of large
//! PLY meshes is never held in memory at once. What megaray does not render is counted
//! per kind and reported once ([`PbrtScene::skipped`]); errors name `file: line L:C`.
//!
//! Beyond pbrt-v4: `ObjectInstance` may appear inside `ObjectBegin` (objects placed in
//! objects: nested instancing, which pbrt-v4 refuses), so that a forest's groves can be
//! instanced again.

mod lex;
mod shapes;

use std::collections::{BTreeMap, HashMap};
use std::path::{Path, PathBuf};

use megaray_base::{Affine, Vec3};

use crate::{ImportError, Material};
use lex::{Lexer, Loc, Tok};
pub use shapes::feed_object;

/// Most numbers one parameter may hold (a corrupt or hostile file claims more).
const MAX_VALUES: usize = 1 << 28;
/// Deepest `Include` nesting.
const MAX_INCLUDE: usize = 32;

/// A shape as the scene gives it, its triangles read when its object is built.
#[derive(Clone, Debug)]
pub struct ShapeDesc {
    /// What the shape is.
    pub kind: ShapeKind,
    /// Shape space to the object's (or, for the world's shapes, to the world).
    pub xform: Affine,
    /// `ReverseOrientation` was in effect: triangles wound the other way.
    pub reverse: bool,
    /// Index into [`PbrtScene::materials`], or `None`.
    pub material: Option<u32>,
    /// Where it was declared (for component names).
    pub place: String,
    /// The file that declared it and where in it (for errors: [`ImportError`]'s path and
    /// location).
    pub declared: (PathBuf, String),
    /// An area light's shape: each triangle wound to face the side its vertex normals face,
    /// when it has them (pbrt's rule for which side emits), so that the winding's front is
    /// the emitting side.
    pub emitting: bool,
}

/// The kinds of shape megaray draws.
#[derive(Clone, Debug)]
pub enum ShapeKind {
    /// `trianglemesh` (and `bilinearmesh`, as two triangles a quad): positions, three
    /// indices a triangle, vertex normals, texture coordinates and colours (RGBA: glTF's
    /// `COLOR_0`; pbrt has none) where given.
    #[allow(missing_docs)]
    Mesh {
        p: Vec<[f32; 3]>,
        indices: Vec<u32>,
        n: Option<Vec<[f32; 3]>>,
        uv: Option<Vec<[f32; 2]>>,
        color: Option<Vec<[f32; 4]>>,
    },
    /// `plymesh`: a PLY file (binary, ASCII, or either gzip-compressed).
    Ply(PathBuf),
}

/// A named object (`ObjectBegin`): its shapes and the objects placed in it.
#[derive(Clone, Debug, Default)]
pub struct ObjectDesc {
    /// Its name (`ObjectBegin "name"`; "world" for object 0).
    pub name: String,
    /// Its shapes, in the order given.
    pub shapes: Vec<ShapeDesc>,
    /// Objects placed in this one: (object index, transform into this object's space).
    pub instances: Vec<(u32, Affine)>,
}

/// The camera of the scene file.
#[derive(Clone, Copy, Debug, PartialEq)]
#[allow(missing_docs)]
pub struct CameraDesc {
    pub eye: Vec3,
    pub at: Vec3,
    pub up: Vec3,
    /// Full field of view of the image's shorter axis, degrees (pbrt's `fov`).
    pub fov: f32,
}

/// A parsed pbrt scene.
#[derive(Clone, Debug, Default)]
pub struct PbrtScene {
    /// Object 0 is the world's own shapes and instances; the named objects follow in the
    /// order they were defined (an object places only objects defined before it).
    pub objects: Vec<ObjectDesc>,
    /// The materials shapes name ([`ShapeDesc::material`]).
    pub materials: Vec<Material>,
    /// The camera (`Camera "perspective"` and the transform before it).
    pub camera: Option<CameraDesc>,
    /// `LightSource "infinite"` with a `filename`: the environment map and its scale.
    pub environment: Option<(PathBuf, f32)>,
    /// `LightSource "distant"`: direction toward the light and its radiance (RGB).
    pub sun: Option<(Vec3, [f32; 3])>,
    /// Image size (`Film`), if given.
    pub resolution: Option<(u32, u32)>,
    /// `AreaLightSource "diffuse"`: the emitting shapes of the world (not of objects).
    pub area_lights: Vec<AreaLightDesc>,
    /// What was skipped, per kind ("Shape sphere": 3).
    pub skipped: BTreeMap<String, u64>,
}

/// A diffuse area light: one shape whose surface emits `radiance` (pbrt's `L` times
/// `scale`), on the side its winding faces or on both.
#[derive(Clone, Debug, PartialEq)]
pub struct AreaLightDesc {
    /// The material of its triangles: one made for it (its shape's material's reflection),
    /// so that a hit on it is known by the material.
    pub material: u32,
    /// Emitted radiance, linear RGB.
    pub radiance: [f32; 3],
    /// Whether both sides emit (pbrt's `twosided`).
    pub two_sided: bool,
    /// Its triangles in world space, wound so that the front emits.
    pub triangles: Vec<[[f32; 3]; 3]>,
}

/// Most area-light triangles a scene may have (each is a light the renderer samples).
pub const MAX_AREA_TRIANGLES: usize = 1 << 16;

/// Graphics state: the current transform and the attributes `AttributeBegin` saves.
#[derive(Clone)]
struct State {
    ctm: Affine,
    reverse: bool,
    material: Option<u32>,
    /// `AreaLightSource "diffuse"`: radiance and two-sidedness of the shapes that follow.
    area: Option<([f32; 3], bool)>,
}

struct Parser {
    scene: PbrtScene,
    state: State,
    stack: Vec<State>,
    named_cs: HashMap<String, Affine>,
    named_materials: HashMap<String, u32>,
    textures: HashMap<String, PathBuf>,
    objects: HashMap<String, u32>,
    /// Each object's levels of instancing: 0 when it places nothing, else one more than the
    /// deepest object it places (at most [`megaray_base::MAX_NESTING`]).
    depth: Vec<u32>,
    /// The object being defined (`ObjectBegin`), else 0 (the world).
    current: u32,
    camera_ctm: Option<(Affine, f32)>,
    /// The files being read (for cycles of `Include`).
    open: Vec<PathBuf>,
    /// The material made for each (shape material, area light) pair.
    emitting_materials: HashMap<(Option<u32>, [u32; 4]), u32>,
}

/// Reads the pbrt-v4 scene `path` (and what it includes).
pub fn read_scene(path: &Path) -> Result<PbrtScene, ImportError> {
    let mut p = Parser {
        scene: PbrtScene {
            objects: vec![ObjectDesc { name: "world".into(), ..Default::default() }],
            ..Default::default()
        },
        state: State { ctm: Affine::IDENTITY, reverse: false, material: None, area: None },
        stack: Vec::new(),
        named_cs: HashMap::new(),
        named_materials: HashMap::new(),
        textures: HashMap::new(),
        objects: HashMap::new(),
        depth: vec![0],
        current: 0,
        camera_ctm: None,
        open: Vec::new(),
        emitting_materials: HashMap::new(),
    };
    p.file(path)?;
    if let Some((ctm, fov)) = p.camera_ctm {
        // The camera transform maps world to camera space (pbrt's camera looks down +z).
        let to_world = ctm.inverse().unwrap_or(Affine::IDENTITY);
        let eye = to_world.point(Vec3::ZERO);
        p.scene.camera = Some(CameraDesc {
            eye,
            at: to_world.point(Vec3::Z),
            up: to_world.vector(Vec3::Y).normalize_or_zero(),
            fov,
        });
    }
    Ok(p.scene)
}

impl Parser {
    fn file(&mut self, path: &Path) -> Result<(), ImportError> {
        let canon = std::fs::canonicalize(path).unwrap_or_else(|_| path.to_path_buf());
        if self.open.contains(&canon) {
            return Err(ImportError::new(path, None, "Include cycle: the file includes itself"));
        }
        if self.open.len() >= MAX_INCLUDE {
            return Err(ImportError::new(path, None, format!("Include nested more than {MAX_INCLUDE} deep")));
        }
        let mut lx = Lexer::open(path)?;
        self.open.push(canon);
        let r = self.statements(&mut lx);
        self.open.pop();
        r
    }

    fn statements(&mut self, lx: &mut Lexer) -> Result<(), ImportError> {
        while let Some((tok, loc)) = lx.next()? {
            let Tok::Ident(word) = tok else {
                return Err(loc.err(format!("expected a statement, found {tok:?}")));
            };
            self.statement(&word, &loc, lx)?;
        }
        Ok(())
    }

    fn statement(&mut self, word: &str, loc: &Loc, lx: &mut Lexer) -> Result<(), ImportError> {
        let ctm = self.state.ctm;
        match word {
            "AttributeBegin" | "TransformBegin" => self.stack.push(self.state.clone()),
            "AttributeEnd" | "TransformEnd" => {
                self.state = self.stack.pop().ok_or_else(|| loc.err(format!("unbalanced {word}")))?;
            }
            "Identity" => self.state.ctm = Affine::IDENTITY,
            "Translate" => {
                let v = nums::<3>(lx, loc)?;
                self.state.ctm = ctm.then_after(&Affine::translation(v3(v)));
            }
            "Scale" => {
                let v = nums::<3>(lx, loc)?;
                self.state.ctm = ctm.then_after(&Affine::scale(v3(v)));
            }
            "Rotate" => {
                let v = nums::<4>(lx, loc)?;
                self.state.ctm = ctm.then_after(&Affine::rotation(v[0], Vec3::new(v[1], v[2], v[3])));
            }
            "LookAt" => {
                let v = nums::<9>(lx, loc)?;
                let m = look_at(v3([v[0], v[1], v[2]]), v3([v[3], v[4], v[5]]), v3([v[6], v[7], v[8]]))
                    .ok_or_else(|| loc.err("LookAt: eye, target and up do not make a view"))?;
                self.state.ctm = ctm.then_after(&m);
            }
            "Transform" | "ConcatTransform" => {
                let v = bracketed_nums(lx, loc, 16)?;
                let m = Affine::from_cols4(std::array::from_fn(|c| std::array::from_fn(|r| v[4 * c + r])));
                self.state.ctm = if word == "Transform" { m } else { ctm.then_after(&m) };
            }
            "CoordinateSystem" => {
                let name = string(lx, loc)?;
                self.named_cs.insert(name, ctm);
            }
            "CoordSysTransform" => {
                let name = string(lx, loc)?;
                self.state.ctm =
                    *self.named_cs.get(&name).ok_or_else(|| loc.err(format!("no coordinate system \"{name}\"")))?;
            }
            "ReverseOrientation" => self.state.reverse = !self.state.reverse,
            "WorldBegin" => {
                self.named_cs.insert("camera".into(), ctm.inverse().unwrap_or(Affine::IDENTITY));
                self.state.ctm = Affine::IDENTITY;
            }
            "WorldEnd" => {}
            "Include" | "Import" => {
                let name = string(lx, loc)?;
                let path = lx.file().parent().unwrap_or(Path::new(".")).join(&name);
                if !path.is_file() {
                    return Err(loc.err(format!("{word} \"{name}\": no such file")));
                }
                self.file(&path)?;
            }
            "Camera" => {
                let (kind, params) = typed(lx, loc)?;
                if kind != "perspective" {
                    self.skip(format!("Camera {kind}"));
                }
                let fov = params.num("fov").unwrap_or(90.0) as f32;
                self.camera_ctm = Some((ctm, fov));
            }
            "Film" => {
                let (_, params) = typed(lx, loc)?;
                if let (Some(x), Some(y)) = (params.num("xresolution"), params.num("yresolution")) {
                    self.scene.resolution = Some((x.clamp(1.0, 65536.0) as u32, y.clamp(1.0, 65536.0) as u32));
                }
            }
            "Sampler" | "PixelFilter" | "Integrator" | "Accelerator" | "ColorSpace" | "Option" | "MakeNamedMedium"
            | "MediumInterface" | "Attribute" => {
                // Settings of pbrt's own rendering: read past them.
                skip_params(lx)?;
                if matches!(word, "MakeNamedMedium" | "MediumInterface" | "Attribute") {
                    self.skip(word.to_string());
                }
            }
            "Texture" => {
                let name = string(lx, loc)?;
                let _ty = string(lx, loc)?;
                let (class, params) = typed(lx, loc)?;
                match (class.as_str(), params.string("filename")) {
                    ("imagemap", Some(f)) => {
                        let p = lx.file().parent().unwrap_or(Path::new(".")).join(f);
                        self.textures.insert(name, p);
                    }
                    _ => self.skip(format!("Texture {class}")),
                }
            }
            "Material" => {
                let (kind, params) = typed(lx, loc)?;
                let id = self.material(format!("material {}", self.scene.materials.len()), &kind, &params);
                self.state.material = Some(id);
            }
            "MakeNamedMaterial" => {
                let name = string(lx, loc)?;
                let params = params(lx)?;
                let kind = params.string("type").unwrap_or("diffuse").to_string();
                let id = self.material(name.clone(), &kind, &params);
                self.named_materials.insert(name, id);
            }
            "NamedMaterial" => {
                let name = string(lx, loc)?;
                let id = *self.named_materials.get(&name).ok_or_else(|| loc.err(format!("no material \"{name}\"")))?;
                self.state.material = Some(id);
            }
            "LightSource" => {
                let (kind, params) = typed(lx, loc)?;
                self.light(&kind, &params, lx.file());
            }
            "AreaLightSource" => {
                let (kind, params) = typed(lx, loc)?;
                self.state.area = None;
                match (kind.as_str(), params.rgb("L")) {
                    ("diffuse", l) => {
                        if l.is_none() && params.get("L").is_some() {
                            self.skip("AreaLightSource L other than rgb (emits white)".into());
                        }
                        let s = params.num("scale").unwrap_or(1.0) as f32;
                        let l = l.unwrap_or([1.0; 3]).map(|c| (c * s).max(0.0));
                        if l.iter().all(|c| c.is_finite()) && l.iter().any(|&c| c > 0.0) {
                            self.state.area = Some((l, params.bool("twosided").unwrap_or(false)));
                        }
                    }
                    _ => self.skip(format!("AreaLightSource {kind}")),
                }
            }
            "Shape" => {
                let (kind, params) = typed(lx, loc)?;
                let place = format!("{}: line {}", loc.file.display(), loc.line);
                if let Some(kind) = shapes::shape(&kind, &params, lx.file(), loc)? {
                    let mut s = ShapeDesc {
                        kind,
                        xform: ctm,
                        reverse: self.state.reverse,
                        material: self.state.material,
                        place,
                        declared: (loc.file.clone(), format!("line {}:{}", loc.line, loc.col)),
                        emitting: false,
                    };
                    if let Some(area) = self.state.area {
                        if self.current == 0 {
                            self.area_light(&mut s, area, loc)?;
                        } else {
                            self.skip("AreaLightSource inside ObjectBegin (drawn, but emits nothing)".into());
                        }
                    }
                    self.scene.objects[self.current as usize].shapes.push(s);
                } else {
                    self.skip(format!("Shape {kind}"));
                }
            }
            "ObjectBegin" => {
                let name = string(lx, loc)?;
                if self.current != 0 {
                    return Err(loc.err(format!("ObjectBegin \"{name}\" inside another object")));
                }
                self.stack.push(self.state.clone());
                self.current = self.scene.objects.len() as u32;
                self.objects.insert(name.clone(), self.current);
                self.scene.objects.push(ObjectDesc { name, ..Default::default() });
                self.depth.push(0);
            }
            "ObjectEnd" => {
                if self.current == 0 {
                    return Err(loc.err("ObjectEnd without ObjectBegin"));
                }
                self.current = 0;
                self.state = self.stack.pop().ok_or_else(|| loc.err("unbalanced ObjectEnd"))?;
            }
            "ObjectInstance" => {
                let name = string(lx, loc)?;
                let o = *self.objects.get(&name).ok_or_else(|| loc.err(format!("no object \"{name}\"")))?;
                if o == self.current {
                    return Err(loc.err(format!("object \"{name}\" placed in itself")));
                }
                if ctm.inverse().is_none() {
                    return Err(loc.err(format!("ObjectInstance \"{name}\": the transform is not invertible")));
                }
                let levels = self.depth[o as usize] + 1;
                if levels > megaray_base::MAX_NESTING {
                    let max = megaray_base::MAX_NESTING;
                    return Err(loc.err(format!(
                        "objects nest more than {max} levels deep (\"{name}\" holds {} levels)",
                        levels - 1
                    )));
                }
                let c = self.current as usize;
                self.depth[c] = self.depth[c].max(levels);
                self.scene.objects[c].instances.push((o, ctm));
            }
            _ => {
                return Err(loc.err(format!("unknown statement {word}")));
            }
        }
        Ok(())
    }

    /// Makes shape `s` (of the world) an area light: its own material, its triangles read
    /// now into [`PbrtScene::area_lights`].
    fn area_light(
        &mut self,
        s: &mut ShapeDesc,
        (radiance, two_sided): ([f32; 3], bool),
        loc: &Loc,
    ) -> Result<(), ImportError> {
        let key = (s.material, [radiance[0].to_bits(), radiance[1].to_bits(), radiance[2].to_bits(), two_sided as u32]);
        let material = match self.emitting_materials.get(&key) {
            Some(&m) => m,
            None => {
                let base = s.material.and_then(|m| self.scene.materials.get(m as usize));
                let mut m =
                    base.cloned().unwrap_or_else(|| Material { diffuse: Some([0.5; 3]), ..Material::default() });
                m.name = format!(
                    "{} (area light {})",
                    if base.is_some() { m.name.as_str() } else { "diffuse" },
                    self.emitting_materials.len()
                );
                self.scene.materials.push(m);
                let id = (self.scene.materials.len() - 1) as u32;
                self.emitting_materials.insert(key, id);
                id
            }
        };
        s.material = Some(material);
        s.emitting = true;
        let mut tris = Triangles::default();
        let one = ObjectDesc { name: String::new(), shapes: vec![s.clone()], instances: Vec::new() };
        feed_object(&one, &crate::ImportOptions::default(), &mut tris, &megaray_base::NoProgress)?;
        let total: usize = self.scene.area_lights.iter().map(|a| a.triangles.len()).sum::<usize>() + tris.0.len();
        if total > MAX_AREA_TRIANGLES {
            return Err(loc.err(format!(
                "more than {MAX_AREA_TRIANGLES} area-light triangles (megaray samples each as a light)"
            )));
        }
        self.scene.area_lights.push(AreaLightDesc { material, radiance, two_sided, triangles: tris.0 });
        Ok(())
    }

    fn skip(&mut self, what: String) {
        *self.scene.skipped.entry(what).or_default() += 1;
    }

    /// A pbrt material as megaray's: diffuse reflectance (or image texture), conductors as
    /// metals, dielectrics as glass, coated ones as diffuse with a clear specular layer.
    fn material(&mut self, name: String, kind: &str, p: &Params) -> u32 {
        let mut m = Material { name, ..Material::default() };
        let rough = p.num("roughness").or(p.num("uroughness")).map(|r| r as f32);
        let tex = p.texture("reflectance").and_then(|t| self.textures.get(t).cloned());
        // A texture that is not there: the material drawn in its colour (or pbrt's 0.5 grey).
        let tex = match tex {
            Some(t) if !t.is_file() => {
                self.skip("Texture imagemap whose file is missing (drawn in the material's colour)".into());
                None
            }
            t => t,
        };
        match kind {
            "diffuse" | "coateddiffuse" | "diffusetransmission" => {
                // The texture is the reflectance (megaray multiplies it by the colour).
                let plain = if tex.is_some() { [1.0; 3] } else { [0.5; 3] };
                m.diffuse = Some(p.rgb("reflectance").unwrap_or(plain));
                m.texture = tex;
                if kind == "coateddiffuse" {
                    m.specular = Some([0.04; 3]);
                    m.roughness = Some(rough.unwrap_or(0.0).clamp(0.0, 1.0));
                    m.shininess = Some(2.0 / (rough.unwrap_or(0.05).max(0.01).powi(2)));
                }
            }
            "conductor" | "coatedconductor" => {
                let f0 = p.rgb("reflectance").unwrap_or_else(|| {
                    let (eta, k) = (p.rgb("eta").unwrap_or([0.2, 0.92, 1.1]), p.rgb("k").unwrap_or([3.9, 2.45, 2.14]));
                    std::array::from_fn(|c| {
                        ((eta[c] - 1.0).powi(2) + k[c] * k[c]) / ((eta[c] + 1.0).powi(2) + k[c] * k[c])
                    })
                });
                m.diffuse = Some(f0);
                m.metallic = Some(1.0);
                m.roughness = Some(rough.unwrap_or(0.0).clamp(0.0, 1.0));
            }
            "dielectric" | "thindielectric" => {
                m.opacity = Some(0.0);
                m.diffuse = Some([1.0; 3]);
            }
            other => {
                self.skip(format!("Material {other} (drawn diffuse)"));
                m.diffuse = Some([0.5; 3]);
            }
        }
        self.scene.materials.push(m);
        (self.scene.materials.len() - 1) as u32
    }

    fn light(&mut self, kind: &str, p: &Params, file: &Path) {
        let ctm = self.state.ctm;
        match (kind, p.string("filename")) {
            ("infinite", Some(f)) => {
                let path = file.parent().unwrap_or(Path::new(".")).join(f);
                self.scene.environment = Some((path, p.num("scale").unwrap_or(1.0) as f32));
            }
            ("distant", _) => {
                let from = v3(p.nums("from").and_then(|v| v.try_into().ok()).unwrap_or([0.0, 0.0, 0.0]));
                let to = v3(p.nums("to").and_then(|v| v.try_into().ok()).unwrap_or([0.0, 0.0, 1.0]));
                let dir = ctm.vector(from - to).normalize_or_zero();
                let l = p.rgb("L").unwrap_or([1.0; 3]);
                let s = p.num("scale").unwrap_or(1.0) as f32;
                self.scene.sun = Some((dir, l.map(|c| c * s)));
            }
            _ => self.skip(format!("LightSource {kind}")),
        }
    }
}

/// Collects triangles (an area light's).
#[derive(Default)]
struct Triangles(Vec<[[f32; 3]; 3]>);

impl crate::TriangleSink for Triangles {
    fn triangle(&mut self, p: [[f32; 3]; 3], _: &crate::TriAttr) -> Result<(), ImportError> {
        self.0.push(p);
        Ok(())
    }
    fn material(&mut self, _: Material) -> u32 {
        crate::NO_MATERIAL
    }
}

fn v3(v: [f32; 3]) -> Vec3 {
    Vec3::new(v[0], v[1], v[2])
}

/// pbrt's `LookAt`: world to camera space (camera at the origin looking down +z, +y up).
fn look_at(eye: Vec3, at: Vec3, up: Vec3) -> Option<Affine> {
    let dir = (at - eye).normalize_or_zero();
    let right = up.normalize_or_zero().cross(dir).normalize_or_zero();
    if dir == Vec3::ZERO || right == Vec3::ZERO {
        return None;
    }
    let new_up = dir.cross(right);
    // Camera to world has columns right, up, dir, eye; its inverse is the map.
    let cam_to_world = Affine([
        [right.x, new_up.x, dir.x, eye.x],
        [right.y, new_up.y, dir.y, eye.y],
        [right.z, new_up.z, dir.z, eye.z],
    ]);
    cam_to_world.inverse()
}

/// `N` numbers, bare or in brackets (`Translate 1 2 3`, `Translate [1 2 3]`).
fn nums<const N: usize>(lx: &mut Lexer, loc: &Loc) -> Result<[f32; N], ImportError> {
    let bracket = matches!(lx.peek()?, Some((Tok::Open, _)));
    if bracket {
        lx.next()?;
    }
    let mut out = [0.0; N];
    for o in out.iter_mut() {
        match lx.next()? {
            Some((Tok::Num(v), _)) => *o = v as f32,
            Some((t, l)) => return Err(l.err(format!("expected a number, found {t:?}"))),
            None => return Err(loc.err("the file ends in the middle of a statement")),
        }
    }
    if bracket {
        match lx.next()? {
            Some((Tok::Close, _)) => {}
            _ => return Err(loc.err(format!("expected {N} numbers and ']'"))),
        }
    }
    Ok(out)
}

fn bracketed_nums(lx: &mut Lexer, loc: &Loc, n: usize) -> Result<Vec<f32>, ImportError> {
    let v = match value(lx, loc)? {
        Value::Nums(v) => v,
        _ => return Err(loc.err(format!("expected {n} numbers"))),
    };
    if v.len() != n {
        return Err(loc.err(format!("expected {n} numbers, found {}", v.len())));
    }
    Ok(v.into_iter().map(|x| x as f32).collect())
}

fn string(lx: &mut Lexer, loc: &Loc) -> Result<String, ImportError> {
    match lx.next()? {
        Some((Tok::Str(s), _)) => Ok(s),
        Some((t, l)) => Err(l.err(format!("expected a quoted string, found {t:?}"))),
        None => Err(loc.err("the file ends in the middle of a statement")),
    }
}

/// A statement's type name and its parameter list.
fn typed(lx: &mut Lexer, loc: &Loc) -> Result<(String, Params), ImportError> {
    let kind = string(lx, loc)?;
    Ok((kind, params(lx)?))
}

#[derive(Clone, Debug)]
enum Value {
    Nums(Vec<f64>),
    Strs(Vec<String>),
    /// Booleans (`"bool twosided" true`).
    Bools(Vec<bool>),
}

/// A parameter list: `"type name" value`, by name.
#[derive(Clone, Debug, Default)]
pub(crate) struct Params(Vec<(String, String, Value)>);

impl Params {
    fn get(&self, name: &str) -> Option<&(String, String, Value)> {
        self.0.iter().find(|p| p.1 == name)
    }
    pub(crate) fn nums(&self, name: &str) -> Option<Vec<f32>> {
        match self.get(name) {
            Some((_, _, Value::Nums(v))) => Some(v.iter().map(|&x| x as f32).collect()),
            _ => None,
        }
    }
    /// The numbers of `name` as given (indices stay exact).
    pub(crate) fn values(&self, name: &str) -> Option<&[f64]> {
        match self.get(name) {
            Some((_, _, Value::Nums(v))) => Some(v),
            _ => None,
        }
    }
    fn bool(&self, name: &str) -> Option<bool> {
        match self.get(name) {
            Some((_, _, Value::Bools(v))) => v.first().copied(),
            _ => None,
        }
    }
    fn num(&self, name: &str) -> Option<f64> {
        self.values(name).and_then(|v| v.first().copied())
    }
    pub(crate) fn string(&self, name: &str) -> Option<&str> {
        match self.get(name) {
            Some((t, _, Value::Strs(v))) if t != "texture" => v.first().map(|s| s.as_str()),
            _ => None,
        }
    }
    fn texture(&self, name: &str) -> Option<&str> {
        match self.get(name) {
            Some((t, _, Value::Strs(v))) if t == "texture" => v.first().map(|s| s.as_str()),
            _ => None,
        }
    }
    fn rgb(&self, name: &str) -> Option<[f32; 3]> {
        match self.get(name) {
            Some((t, _, Value::Nums(v))) if t == "rgb" && v.len() == 3 => Some([v[0] as f32, v[1] as f32, v[2] as f32]),
            Some((t, _, Value::Nums(v))) if (t == "float" || t == "spectrum") && v.len() == 1 => Some([v[0] as f32; 3]),
            _ => None,
        }
    }
}

fn params(lx: &mut Lexer) -> Result<Params, ImportError> {
    let mut out = Params::default();
    while let Some((Tok::Str(_), _)) = lx.peek()? {
        let Some((Tok::Str(decl), at)) = lx.next()? else { unreachable!("peeked a string") };
        let mut it = decl.split_whitespace();
        let (Some(ty), Some(name), None) = (it.next(), it.next(), it.next()) else {
            return Err(at.err(format!("bad parameter declaration \"{decl}\" (expected \"type name\")")));
        };
        let v = value(lx, &at)?;
        out.0.push((ty.to_string(), name.to_string(), v));
    }
    Ok(out)
}

fn skip_params(lx: &mut Lexer) -> Result<(), ImportError> {
    if let Some((Tok::Str(_), _)) = lx.peek()? {
        // A type name (`Sampler "sobol"`).
        lx.next()?;
    }
    params(lx).map(|_| ())
}

/// One value, bare or a bracketed list (numbers, strings or bools).
fn value(lx: &mut Lexer, loc: &Loc) -> Result<Value, ImportError> {
    let one = |t: Tok, l: &Loc| -> Result<Value, ImportError> {
        Ok(match t {
            Tok::Num(v) => Value::Nums(vec![v]),
            Tok::Str(s) => Value::Strs(vec![s]),
            Tok::Ident(w) if w == "true" || w == "false" => Value::Bools(vec![w == "true"]),
            t => return Err(l.err(format!("expected a value, found {t:?}"))),
        })
    };
    match lx.next()? {
        Some((Tok::Open, _)) => {}
        Some((t, l)) => return one(t, &l),
        None => return Err(loc.err("the file ends where a value was expected")),
    }
    let (mut nums, mut strs, mut bools) = (Vec::new(), Vec::new(), Vec::new());
    loop {
        match lx.next()? {
            Some((Tok::Close, _)) => break,
            Some((Tok::Num(v), _)) => nums.push(v),
            Some((Tok::Str(s), _)) => strs.push(s),
            Some((Tok::Ident(w), _)) if w == "true" || w == "false" => bools.push(w == "true"),
            Some((t, l)) => return Err(l.err(format!("unexpected {t:?} in a list"))),
            None => return Err(loc.err("unterminated list (no ']')")),
        }
        if nums.len() + strs.len() + bools.len() > MAX_VALUES {
            return Err(loc.err(format!("a list of more than {MAX_VALUES} values")));
        }
    }
    Ok(match (nums.is_empty(), strs.is_empty()) {
        (false, true) => Value::Nums(nums),
        (true, false) => Value::Strs(strs),
        (true, true) if !bools.is_empty() => Value::Bools(bools),
        (true, true) => Value::Nums(Vec::new()),
        _ => return Err(loc.err("a list of numbers and strings mixed")),
    })
}
