//! Saved views: the camera, the shading and what is shown (hidden, isolated and X-rayed
//! components by name, section planes, the highlighted pick), as a small JSON document.
//! The viewer writes one beside each screenshot, `megaray render --view FILE` renders it,
//! and `megaray serve` keeps the current one in the page's address so that a link opens the
//! same view.
//!
//! ```json
//! {"eye":[1,2,3],"yaw":0.5,"pitch":-0.2,"fov":60,"shader":"auto","sky":false,
//!  "hidden":["car.obj/door"],"xray":[],"sections":[{"normal":[0,0,1],"offset":0.1}],
//!  "highlight":"car.obj/wheel"}
//! ```
//!
//! With most components hidden, `"shown"` lists the others instead of `"hidden"` (an
//! isolated part stays one name however large the model).

use megaray_base::Vec3;
use megaray_render::{Builtin, Section, Visibility};
use megaray_scene::Components;
use serde_json::{json, Value};

use crate::camera::Pose;

/// A saved view (see the module documentation).
#[derive(Clone, Debug, PartialEq)]
pub struct Viewpoint {
    pub pose: Pose,
    /// Vertical field of view, degrees.
    pub fov: f32,
    pub shader: Builtin,
    /// Whether the sky lights the scene (the viewer's K).
    pub sky: bool,
    /// What is shown: hidden and X-rayed components, sections.
    pub shown: Visibility,
    /// The highlighted (picked) component.
    pub highlight: Option<u32>,
}

/// Bytes a viewpoint document may have (it travels in a page's address and messages).
pub const MAX_BYTES: usize = 3072;

fn names(comps: &Components, flags: &[bool], want: bool) -> Vec<String> {
    (0..comps.names.len())
        .filter(|&i| flags.get(i).copied().unwrap_or(false) == want)
        .map(|i| comps.name(i as u32).to_string())
        .collect()
}

fn vec3(v: &Value, what: &str) -> Result<Vec3, String> {
    let a = v.as_array().filter(|a| a.len() == 3).ok_or_else(|| format!("{what}: expected [x, y, z]"))?;
    let f: Vec<f32> = a.iter().filter_map(Value::as_f64).map(|x| x as f32).filter(|x| x.is_finite()).collect();
    (f.len() == 3).then(|| Vec3::new(f[0], f[1], f[2])).ok_or_else(|| format!("{what}: expected three numbers"))
}

fn num(v: &Value, key: &str) -> Result<f32, String> {
    v.get(key)
        .and_then(Value::as_f64)
        .map(|x| x as f32)
        .filter(|x| x.is_finite())
        .ok_or_else(|| format!("\"{key}\": expected a number"))
}

/// Per component, whether `list` names it; an unknown name is an error.
fn flags(comps: &Components, list: Option<&Value>, key: &str) -> Result<Option<Vec<bool>>, String> {
    let Some(list) = list else { return Ok(None) };
    let list = list.as_array().ok_or_else(|| format!("\"{key}\": expected a list of names"))?;
    let mut out = vec![false; comps.names.len()];
    for n in list {
        let n = n.as_str().ok_or_else(|| format!("\"{key}\": expected names"))?;
        let i = comps.names.iter().position(|c| c == n).ok_or_else(|| format!("\"{key}\": no component {n:?} here"))?;
        out[i] = true;
    }
    Ok(Some(out))
}

impl Viewpoint {
    /// The JSON document, naming components by their names in `comps`.
    pub fn to_json(&self, comps: &Components) -> String {
        self.to_value(comps).to_string()
    }

    /// [`Viewpoint::to_json`] as a JSON value.
    pub fn to_value(&self, comps: &Components) -> Value {
        let n = comps.names.len();
        let s = &self.shown;
        let hidden = s.hidden.iter().filter(|&&h| h).count();
        let mut v = json!({
            "eye": self.pose.eye.to_array(), "yaw": self.pose.yaw, "pitch": self.pose.pitch, "fov": self.fov,
            "shader": self.shader.name(), "sky": self.sky,
            "xray": names(comps, &s.xray, true),
            "sections": s.sections.iter().map(|s| json!({
                "normal": s.normal.to_array(), "offset": s.offset,
                "only": s.only.as_ref().map(|o| names(comps, o, true)),
            })).collect::<Vec<_>>(),
            "highlight": self.highlight.map(|c| comps.name(c)),
        });
        if hidden * 2 > n {
            v["shown"] = names(comps, &s.hidden, false).into();
        } else {
            v["hidden"] = names(comps, &s.hidden, true).into();
        }
        v
    }

    /// Reads a document against the scene's components; `Err` says what is wrong.
    pub fn from_json(text: &str, comps: &Components) -> Result<Viewpoint, String> {
        if text.len() > MAX_BYTES {
            return Err(format!("{} bytes (at most {MAX_BYTES})", text.len()));
        }
        let v: Value = serde_json::from_str(text).map_err(|e| format!("not JSON ({e})"))?;
        if !v.is_object() {
            return Err("expected a JSON object".into());
        }
        let pose = Pose {
            eye: vec3(v.get("eye").unwrap_or(&Value::Null), "\"eye\"")?,
            yaw: num(&v, "yaw")?,
            pitch: num(&v, "pitch")?.clamp(-1.553, 1.553),
        };
        let fov = num(&v, "fov")?;
        if !(1.0..=170.0).contains(&fov) {
            return Err(format!("\"fov\": {fov} degrees (1 to 170)"));
        }
        let shader = match v.get("shader") {
            None => Builtin::Auto,
            Some(s) => s.as_str().ok_or("\"shader\": expected a name")?.parse::<Builtin>()?,
        };
        let n = comps.names.len();
        let hidden = match (flags(comps, v.get("hidden"), "hidden")?, flags(comps, v.get("shown"), "shown")?) {
            (Some(_), Some(_)) => return Err("give \"hidden\" or \"shown\", not both".into()),
            (Some(h), None) => h,
            (None, Some(s)) => s.iter().map(|&x| !x).collect(),
            (None, None) => vec![false; n],
        };
        let xray = flags(comps, v.get("xray"), "xray")?.unwrap_or_else(|| vec![false; n]);
        let mut sections = Vec::new();
        for s in v.get("sections").and_then(Value::as_array).into_iter().flatten() {
            let normal = vec3(s.get("normal").unwrap_or(&Value::Null), "section \"normal\"")?.normalize_or_zero();
            if normal == Vec3::ZERO {
                return Err("a section's normal is zero".into());
            }
            let only = flags(comps, s.get("only").filter(|o| !o.is_null()), "only")?;
            sections.push(Section { normal, offset: num(s, "offset")?, only });
        }
        let highlight = match v.get("highlight").and_then(Value::as_str) {
            None => None,
            Some(name) => Some(
                comps
                    .names
                    .iter()
                    .position(|c| c == name)
                    .ok_or_else(|| format!("\"highlight\": no component {name:?} here"))? as u32,
            ),
        };
        let sky = v.get("sky").and_then(Value::as_bool).unwrap_or(false);
        Ok(Viewpoint { pose, fov, shader, sky, shown: Visibility { hidden, xray, sections }, highlight })
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn comps(n: usize) -> Components {
        Components { names: (0..n).map(|i| format!("m.obj/p{i}")).collect(), tri_counts: vec![1; n], runs: vec![] }
    }

    #[test]
    fn a_viewpoint_round_trips_through_json() {
        let c = comps(5);
        let mut only = vec![false; 5];
        only[3] = true;
        let vp = Viewpoint {
            pose: Pose { eye: Vec3::new(1.0, -2.0, 3.5), yaw: 0.25, pitch: -0.5 },
            fov: 45.0,
            shader: Builtin::Env,
            sky: true,
            shown: Visibility {
                hidden: vec![false, true, false, false, false],
                xray: vec![false, false, true, false, false],
                sections: vec![Section { only: Some(only), ..Section::new(Vec3::Z, Vec3::Y) }],
            },
            highlight: Some(4),
        };
        let text = vp.to_json(&c);
        assert_eq!(Viewpoint::from_json(&text, &c).unwrap(), vp);
        // Isolated: one name, not the rest.
        let mut iso = vp.clone();
        iso.shown.hidden = vec![true, true, true, false, true];
        let text = iso.to_json(&c);
        assert!(text.contains("\"shown\":[\"m.obj/p3\"]") && !text.contains("hidden"), "{text}");
        assert_eq!(Viewpoint::from_json(&text, &c).unwrap(), iso);
    }

    #[test]
    fn bad_documents_say_what_is_wrong() {
        let c = comps(2);
        let ok = r#"{"eye":[0,0,0],"yaw":0,"pitch":0,"fov":60}"#;
        assert!(Viewpoint::from_json(ok, &c).is_ok());
        for (text, says) in [
            ("[]", "object"),
            ("{", "not JSON"),
            (r#"{"eye":[0,0],"yaw":0,"pitch":0,"fov":60}"#, "eye"),
            (r#"{"eye":[0,0,0],"yaw":0,"pitch":0,"fov":600}"#, "fov"),
            (r#"{"eye":[0,0,0],"yaw":0,"pitch":0,"fov":60,"hidden":["nope"]}"#, "no component \"nope\""),
            (r#"{"eye":[0,0,0],"yaw":0,"pitch":0,"fov":60,"shader":"toon"}"#, "toon"),
            (r#"{"eye":[0,0,0],"yaw":0,"pitch":0,"fov":60,"sections":[{"normal":[0,0,0],"offset":1}]}"#, "zero"),
        ] {
            let e = Viewpoint::from_json(text, &c).unwrap_err();
            assert!(e.contains(says), "{text}: {e}");
        }
        assert!(Viewpoint::from_json(&" ".repeat(MAX_BYTES + 1), &c).unwrap_err().contains("at most"));
    }
}
