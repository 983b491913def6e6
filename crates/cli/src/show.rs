//! What is shown of the model, from the command line: `--hide`, `--isolate`, `--xray` by
//! component name pattern, `--section` planes and `--section-box`, for `render`, `view` and
//! `serve` alike ([`megaray_render::Visibility`]).

use std::sync::Arc;

use anyhow::{bail, Result};
use clap::Args;
use megaray_base::Vec3;
use megaray_render::{Section, Visibility};
use megaray_scene::Components;

#[derive(Args, Clone, Debug, Default)]
pub struct ShowArgs {
    /// Hide the components whose name matches GLOB (`*` any text, `?` one character; names
    /// as `megaray info --parts` lists them: `car.obj/body/wheel`). Repeatable.
    #[arg(long, value_name = "GLOB")]
    pub hide: Vec<String>,
    /// Show only the components matching GLOB (repeatable: any of them).
    #[arg(long, value_name = "GLOB")]
    pub isolate: Vec<String>,
    /// Draw the components matching GLOB see-through (X-ray); other rays pass them by.
    #[arg(long, value_name = "GLOB")]
    pub xray: Vec<String>,
    /// A section plane through point X,Y,Z with normal NX,NY,NZ: the side the normal points
    /// to is cut away, and cut closed parts show a solid cap. `@GLOB` limits it to the
    /// matching components. Repeatable: the planes keep the intersection of their sides.
    #[arg(long, value_name = "X,Y,Z,NX,NY,NZ[@GLOB]", allow_hyphen_values = true)]
    pub section: Vec<String>,
    /// Keep only what lies inside the box X0,Y0,Z0,X1,Y1,Z1 (six section planes).
    #[arg(long, value_name = "X0,Y0,Z0,X1,Y1,Z1", allow_hyphen_values = true)]
    pub section_box: Option<String>,
}

/// Reads a saved view (`.view.json`, as the viewer writes beside each screenshot) against
/// the scene's components.
pub fn read_viewpoint(path: &std::path::Path, comps: &Components) -> Result<megaray_view::Viewpoint> {
    use std::io::Read;
    let mut text = String::new();
    let max = megaray_view::viewpoint::MAX_BYTES as u64;
    std::fs::File::open(path)
        .and_then(|f| f.take(max + 1).read_to_string(&mut text))
        .map_err(|e| anyhow::anyhow!("{}: cannot read the view: {e}", path.display()))?;
    megaray_view::Viewpoint::from_json(text.trim(), comps).map_err(|e| anyhow::anyhow!("{}: {e}", path.display()))
}

impl ShowArgs {
    /// Whether any option asks for something hidden, X-rayed or cut.
    pub fn any(&self) -> bool {
        !(self.hide.is_empty() && self.isolate.is_empty() && self.xray.is_empty() && self.section.is_empty())
            || self.section_box.is_some()
    }
}

/// Whether `name` matches `glob` (`*`: any run of characters, `?`: one).
pub fn glob_match(glob: &str, name: &str) -> bool {
    let (g, n): (Vec<char>, Vec<char>) = (glob.chars().collect(), name.chars().collect());
    // Iterative wildcard matching with one backtrack point (the last `*`).
    let (mut i, mut j, mut star, mut mark) = (0, 0, None, 0);
    while j < n.len() {
        if i < g.len() && (g[i] == '?' || g[i] == n[j]) {
            (i, j) = (i + 1, j + 1);
        } else if i < g.len() && g[i] == '*' {
            (star, mark, i) = (Some(i), j, i + 1);
        } else if let Some(s) = star {
            (i, mark, j) = (s + 1, mark + 1, mark + 1);
        } else {
            return false;
        }
    }
    g[i..].iter().all(|&c| c == '*')
}

/// Per component, whether it matches any of `globs`; an error names a pattern that matches
/// nothing.
fn matching(comps: &Components, globs: &[String], option: &str) -> Result<Vec<bool>> {
    let mut out = vec![false; comps.names.len()];
    for g in globs {
        let mut any = false;
        for (k, n) in comps.names.iter().enumerate() {
            if glob_match(g, n) {
                out[k] = true;
                any = true;
            }
        }
        if !any {
            match comps.names.len() {
                0 => bail!(
                    "--{option} {g:?}: the scene names no components (it was built from one input without groups)"
                ),
                n => bail!(
                    "--{option} {g:?} matches none of the scene's {n} components (megaray info --parts lists them)"
                ),
            }
        }
    }
    Ok(out)
}

fn numbers(s: &str, n: usize, option: &str) -> Result<Vec<f32>> {
    let v: Vec<f32> = s.split(',').map(|x| x.trim().parse::<f32>()).collect::<Result<_, _>>().unwrap_or_default();
    if v.len() != n || !v.iter().all(|x| x.is_finite()) {
        bail!("--{option} {s:?}: expected {n} numbers separated by commas");
    }
    Ok(v)
}

impl ShowArgs {
    /// The visibility these options ask for in a scene of components `comps` (`None`: show
    /// everything).
    pub fn visibility(&self, comps: &Components) -> Result<Option<Arc<Visibility>>> {
        let mut hidden = matching(comps, &self.hide, "hide")?;
        if !self.isolate.is_empty() {
            let keep = matching(comps, &self.isolate, "isolate")?;
            for (h, k) in hidden.iter_mut().zip(keep) {
                *h |= !k;
            }
        }
        let xray = matching(comps, &self.xray, "xray")?;
        let mut sections = Vec::new();
        for s in &self.section {
            let (nums, glob) = match s.split_once('@') {
                Some((a, g)) => (a, Some(g)),
                None => (s.as_str(), None),
            };
            let v = numbers(nums, 6, "section")?;
            let normal = Vec3::new(v[3], v[4], v[5]);
            if normal.length() == 0.0 {
                bail!("--section {s:?}: the normal is zero");
            }
            let mut plane = Section::new(Vec3::new(v[0], v[1], v[2]), normal);
            if let Some(g) = glob {
                plane.only = Some(matching(comps, &[g.to_string()], "section")?);
            }
            sections.push(plane);
        }
        if let Some(b) = &self.section_box {
            let v = numbers(b, 6, "section-box")?;
            let (lo, hi) = (Vec3::new(v[0], v[1], v[2]), Vec3::new(v[3], v[4], v[5]));
            if !(lo.cmple(hi).all()) {
                bail!("--section-box {b:?}: the first corner must be below the second on every axis");
            }
            sections.extend(Section::box_of(lo, hi));
        }
        let vis = Visibility { hidden, xray, sections };
        Ok((!vis.is_empty()).then(|| Arc::new(vis)))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn globs_match_as_shells_do() {
        for (g, n, m) in [
            ("*", "a/b", true),
            ("car.obj/*", "car.obj/body/wheel", true),
            ("*wheel", "car.obj/body/wheel", true),
            ("*wheel", "car.obj/wheel/hub", false),
            ("*wh??l*", "x/wheel/hub", true),
            ("body", "car.obj/body", false),
            ("a*b*c", "aXbYbZc", true),
            ("a*b*c", "aXbYbZ", false),
            ("", "", true),
        ] {
            assert_eq!(glob_match(g, n), m, "{g} against {n}");
        }
    }

    #[test]
    fn options_become_a_visibility() {
        let comps = Components {
            names: vec!["m.obj/wall".into(), "m.obj/back".into(), "m.obj/wheel".into()],
            tri_counts: vec![1, 1, 1],
            runs: vec![],
        };
        let none = ShowArgs::default();
        assert!(none.visibility(&comps).unwrap().is_none());
        let a = ShowArgs { isolate: vec!["*w*".into()], xray: vec!["*wall".into()], ..Default::default() };
        let v = a.visibility(&comps).unwrap().unwrap();
        assert_eq!((v.hidden.clone(), v.xray.clone()), (vec![false, true, false], vec![true, false, false]));
        let a = ShowArgs { section: vec!["0,0,1,0,0,2@*back".into()], ..Default::default() };
        let v = a.visibility(&comps).unwrap().unwrap();
        assert_eq!((v.sections[0].normal, v.sections[0].offset), (Vec3::Z, 1.0));
        assert_eq!(v.sections[0].only, Some(vec![false, true, false]));
        for (bad, says) in [
            (ShowArgs { hide: vec!["*door*".into()], ..Default::default() }, "matches none"),
            (ShowArgs { section: vec!["1,2,3".into()], ..Default::default() }, "6 numbers"),
            (ShowArgs { section: vec!["0,0,0,0,0,0".into()], ..Default::default() }, "normal is zero"),
            (ShowArgs { section_box: Some("1,1,1,0,0,0".into()), ..Default::default() }, "below"),
        ] {
            let e = bad.visibility(&comps).unwrap_err().to_string();
            assert!(e.contains(says), "{e}");
        }
    }
}
