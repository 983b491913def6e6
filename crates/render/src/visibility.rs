//! What is shown of the model: hidden and X-rayed components, and section planes (with solid
//! caps on the cut parts). Nothing is rebuilt and nothing is kept per triangle: every ray
//! goes through a [`Filtered`] caster that clips it to the kept side of the section planes
//! and steps past the hits it must not see (a hidden component, a part a plane limited to
//! some components cuts away), so shadows, reflections and paged tracing all see the same
//! model. Camera rays also see X-rayed components, as faint layers over what lies behind.

use megaray_base::{Ray, Vec3};
use megaray_scene::Scene;
use megaray_trace::{Hit, Memo, RayCaster, RayCone, Suspended};

/// A section plane: the points `p` with `normal · p > offset` are cut away (the side the
/// normal points to), of every component or of those `only` marks.
#[derive(Clone, Debug, PartialEq)]
pub struct Section {
    /// Unit normal, toward the side cut away.
    pub normal: Vec3,
    /// `normal · p` of the plane's points.
    pub offset: f32,
    /// Per component: whether the plane cuts it (`None`: every component).
    pub only: Option<Vec<bool>>,
}

impl Section {
    /// The plane through `point` with normal `normal` (normalised here).
    pub fn new(point: Vec3, normal: Vec3) -> Section {
        let n = normal.normalize_or_zero();
        Section { normal: n, offset: n.dot(point), only: None }
    }

    /// The six planes that keep the inside of the box `lo`..`hi`.
    pub fn box_of(lo: Vec3, hi: Vec3) -> Vec<Section> {
        vec![
            Section::new(hi, Vec3::X),
            Section::new(hi, Vec3::Y),
            Section::new(hi, Vec3::Z),
            Section::new(lo, -Vec3::X),
            Section::new(lo, -Vec3::Y),
            Section::new(lo, -Vec3::Z),
        ]
    }

    fn cuts(&self, p: Vec3) -> bool {
        self.normal.dot(p) > self.offset
    }
}

/// Hidden and X-rayed components and section planes (see the module documentation).
#[derive(Clone, Debug, Default, PartialEq)]
pub struct Visibility {
    /// Per component: not drawn at all (hide, or everything but the isolated ones).
    pub hidden: Vec<bool>,
    /// Per component: drawn see-through by camera rays, invisible to every other ray.
    pub xray: Vec<bool>,
    /// The kept region is the intersection of the planes' kept half-spaces.
    pub sections: Vec<Section>,
}

/// Hits a ray may step past before it gives up (a pathological stack of hidden surfaces).
const MAX_SKIPS: usize = 256;
/// X-ray layers a camera ray shows before what lies behind them.
const MAX_LAYERS: u32 = 4;
/// How much of what lies behind an X-ray layer shows through it.
const XRAY_THROUGH: f32 = 0.75;
/// The colour of section caps (linear RGB).
pub const CAP_COLOR: [f32; 3] = [0.75, 0.22, 0.16];

impl Visibility {
    /// Whether it shows everything (no filter needed).
    pub fn is_empty(&self) -> bool {
        !self.hidden.contains(&true) && !self.xray.contains(&true) && self.sections.is_empty()
    }

    fn flag(v: &[bool], c: Option<u32>) -> bool {
        c.is_some_and(|c| v.get(c as usize).copied().unwrap_or(false))
    }

    /// Whether component `c` is X-rayed.
    pub fn is_xray(&self, c: Option<u32>) -> bool {
        Self::flag(&self.xray, c)
    }

    /// Whether rays must look at each hit (hidden or X-rayed components, planes limited to
    /// some components); without, clipping to the planes is all.
    fn per_hit(&self) -> bool {
        self.hidden.contains(&true) || self.xray.contains(&true) || self.sections.iter().any(|s| s.only.is_some())
    }

    /// `ray`'s interval clipped to the planes that cut every component: `(t0, t1)` and the
    /// plane the ray enters the kept region through at `t0` (if it starts outside).
    pub fn clip(&self, ray: &Ray) -> (f32, f32, Option<usize>) {
        let (mut t0, mut t1, mut entered) = (ray.t_min.max(0.0), ray.t_max, None);
        for (k, s) in self.sections.iter().enumerate().filter(|(_, s)| s.only.is_none()) {
            let (side, slope) = (s.normal.dot(ray.org) - s.offset, s.normal.dot(ray.dir));
            if slope == 0.0 {
                if side > 0.0 {
                    return (1.0, 0.0, None);
                }
                continue;
            }
            let t = -side / slope;
            if slope > 0.0 {
                t1 = t1.min(t);
            } else if t > t0 {
                (t0, entered) = (t, Some(k));
            }
        }
        (t0, t1, entered)
    }

    /// Whether a hit at `p` of component `c` is not seen (by camera rays when
    /// `xray_seen`, which see X-rayed components).
    pub fn skips(&self, c: Option<u32>, p: Vec3, xray_seen: bool) -> bool {
        Self::flag(&self.hidden, c)
            || (!xray_seen && Self::flag(&self.xray, c))
            || self.sections.iter().any(|s| s.only.as_ref().is_some_and(|o| Self::flag(o, c)) && s.cuts(p))
    }
}

/// A caster that shows rays only what [`Visibility`] leaves (with no visibility, it passes
/// every query straight through).
pub struct Filtered<'a, C: RayCaster + ?Sized> {
    inner: &'a mut C,
    vis: Option<&'a Visibility>,
    /// Whether the next queries are a camera ray's (which sees X-rayed components).
    pub xray_seen: bool,
}

impl<'a, C: RayCaster + ?Sized> Filtered<'a, C> {
    /// `inner` filtered by `vis` (an empty visibility, or none, filters nothing).
    pub fn new(inner: &'a mut C, vis: Option<&'a Visibility>) -> Self {
        Filtered { inner, vis: vis.filter(|v| !v.is_empty()), xray_seen: false }
    }

    /// The visibility it applies, if any.
    pub fn visibility(&self) -> Option<&'a Visibility> {
        self.vis
    }

    fn closest(&mut self, ray: &Ray, cone: Option<&RayCone>) -> Result<Option<Hit>, Suspended> {
        let Some(vis) = self.vis else {
            return match cone {
                Some(c) => self.inner.intersect_cone(ray, c),
                None => self.inner.intersect(ray),
            };
        };
        let (t0, t1, _) = vis.clip(ray);
        if t0 >= t1 {
            return Ok(None);
        }
        let mut r = Ray { t_min: t0, t_max: t1, ..*ray };
        for _ in 0..MAX_SKIPS {
            let hit = match cone {
                Some(c) => self.inner.intersect_cone(&r, c)?,
                None => self.inner.intersect(&r)?,
            };
            let Some(h) = hit else { return Ok(None) };
            if !vis.per_hit() {
                return Ok(Some(h));
            }
            let c = self.inner.scene().components().of(h.part, h.prim);
            if !vis.skips(c, r.org + r.dir * h.t, self.xray_seen) {
                return Ok(Some(h));
            }
            r.t_min = f32::from_bits(h.t.to_bits() + 1);
        }
        Ok(None)
    }

    fn any(&mut self, ray: &Ray, cone: Option<&RayCone>) -> Result<bool, Suspended> {
        match self.vis {
            Some(v) if v.per_hit() => Ok(self.closest(ray, cone)?.is_some()),
            Some(v) => {
                let (t0, t1, _) = v.clip(ray);
                if t0 >= t1 {
                    return Ok(false);
                }
                let r = Ray { t_min: t0, t_max: t1, ..*ray };
                match cone {
                    Some(c) => self.inner.occluded_cone(&r, c),
                    None => self.inner.occluded(&r),
                }
            }
            None => match cone {
                Some(c) => self.inner.occluded_cone(ray, c),
                None => self.inner.occluded(ray),
            },
        }
    }
}

impl<C: RayCaster + ?Sized> RayCaster for Filtered<'_, C> {
    fn scene(&self) -> &Scene {
        self.inner.scene()
    }
    fn bounds(&self) -> Option<megaray_base::Aabb> {
        self.inner.bounds()
    }
    fn intersect(&mut self, ray: &Ray) -> Result<Option<Hit>, Suspended> {
        self.closest(ray, None)
    }
    fn occluded(&mut self, ray: &Ray) -> Result<bool, Suspended> {
        self.any(ray, None)
    }
    fn intersect_cone(&mut self, ray: &Ray, cone: &RayCone) -> Result<Option<Hit>, Suspended> {
        self.closest(ray, Some(cone))
    }
    fn occluded_cone(&mut self, ray: &Ray, cone: &RayCone) -> Result<bool, Suspended> {
        self.any(ray, Some(cone))
    }
    fn take_approx(&mut self) -> bool {
        self.inner.take_approx()
    }
    fn mark(&mut self) -> usize {
        self.inner.mark()
    }
    fn checkpoint(&mut self, mark: usize, memo: Memo) {
        self.inner.checkpoint(mark, memo)
    }
    fn recall(&mut self) -> Option<Memo> {
        self.inner.recall()
    }
}

/// What a camera ray sees under a visibility: the X-ray layers in front (their count and
/// summed ghost colour, already weighted), then the hit behind them, and whether that hit is
/// a section cap (the ray entered the kept region inside a closed part: the first surface it
/// meets there is a back face).
pub(crate) struct CameraView {
    pub layers: u32,
    pub ghost: Vec3,
    pub hit: Option<Hit>,
    /// The cap's distance along the ray and normal (facing the ray).
    pub cap: Option<(f32, Vec3)>,
}

/// Traces camera ray `ray` through `f` as [`CameraView`] describes.
pub(crate) fn camera_view<C: RayCaster + ?Sized>(
    f: &mut Filtered<'_, C>,
    ray: &Ray,
    cone: &RayCone,
) -> Result<CameraView, Suspended> {
    let Some(vis) = f.visibility() else {
        let hit = f.intersect_cone(ray, cone)?;
        return Ok(CameraView { layers: 0, ghost: Vec3::ZERO, hit, cap: None });
    };
    let mut view = CameraView { layers: 0, ghost: Vec3::ZERO, hit: None, cap: None };
    let mut r = *ray;
    f.xray_seen = true;
    let mut through = 1.0;
    let found = loop {
        let hit = match f.intersect_cone(&r, cone) {
            Ok(h) => h,
            Err(e) => {
                f.xray_seen = false;
                return Err(e);
            }
        };
        let Some(h) = hit else { break None };
        let c = f.scene().components().of(h.part, h.prim);
        if !vis.is_xray(c) || view.layers >= MAX_LAYERS {
            break Some(h);
        }
        // A faint glass-blue layer, brighter where the surface faces the eye.
        let ng = h.geometric_normal().normalize_or_zero();
        let facing = ng.dot(ray.dir.normalize_or_zero()).abs();
        view.ghost += Vec3::new(0.55, 0.75, 1.0) * ((0.2 + 0.5 * facing) * through * (1.0 - XRAY_THROUGH));
        through *= XRAY_THROUGH;
        view.layers += 1;
        r.t_min = f32::from_bits(h.t.to_bits() + 1);
    };
    f.xray_seen = false;
    let (t0, _, entered) = vis.clip(ray);
    if let (Some(k), Some(h)) = (entered, &found) {
        if t0 > ray.t_min && h.geometric_normal().dot(ray.dir) > 0.0 {
            view.cap = Some((t0, vis.sections[k].normal));
        }
    }
    view.hit = found;
    Ok(view)
}

/// How much of what lies behind `layers` X-ray layers shows.
pub(crate) fn through(layers: u32) -> f32 {
    XRAY_THROUGH.powi(layers as i32)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn rays_are_clipped_to_the_kept_side() {
        let v = Visibility { sections: vec![Section::new(Vec3::ZERO, Vec3::Z)], ..Default::default() };
        // From z = 5 toward -z: enters the kept side (z <= 0) at t = 5, through plane 0.
        let r = Ray::new(Vec3::new(0.0, 0.0, 5.0), -Vec3::Z);
        assert_eq!(v.clip(&r), (5.0, f32::INFINITY, Some(0)));
        // From z = -5 toward +z: leaves it at t = 5.
        let r = Ray::new(Vec3::new(0.0, 0.0, -5.0), Vec3::Z);
        assert_eq!(v.clip(&r), (0.0, 5.0, None));
        // Parallel, on the cut side: nothing.
        let r = Ray::new(Vec3::new(0.0, 0.0, 1.0), Vec3::X);
        let (t0, t1, _) = v.clip(&r);
        assert!(t0 >= t1);
        // A box: the intersection of six half-spaces.
        let b = Visibility { sections: Section::box_of(Vec3::splat(-1.0), Vec3::splat(1.0)), ..Default::default() };
        let r = Ray::new(Vec3::new(-5.0, 0.5, 0.0), Vec3::X);
        let (t0, t1, k) = b.clip(&r);
        assert_eq!((t0, t1), (4.0, 6.0));
        assert_eq!(b.sections[k.unwrap()].normal, -Vec3::X);
    }

    #[test]
    fn hits_are_skipped_by_component() {
        let mut only = vec![false; 3];
        only[2] = true;
        let v = Visibility {
            hidden: vec![true, false, false],
            xray: vec![false, true, false],
            sections: vec![Section { only: Some(only), ..Section::new(Vec3::ZERO, Vec3::Y) }],
        };
        let (up, down) = (Vec3::new(0.0, 1.0, 0.0), Vec3::new(0.0, -1.0, 0.0));
        assert!(v.skips(Some(0), down, true), "hidden");
        assert!(v.skips(Some(1), down, false) && !v.skips(Some(1), down, true), "X-ray: seen by camera rays only");
        assert!(v.skips(Some(2), up, false) && !v.skips(Some(2), down, false), "the plane cuts component 2");
        assert!(!v.skips(Some(1), up, true), "but not component 1");
        assert!(!v.skips(None, up, false), "unnamed triangles are shown");
        assert!(Visibility::default().is_empty());
        assert!(!v.is_empty());
    }
}
