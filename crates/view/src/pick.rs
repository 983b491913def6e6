//! Exact picking: one ray through the full-detail index (a paged tracer loads the tiles
//! along it and waits for them; no level of detail, whatever the frame showed), named by the
//! scene's components, with the next surface behind the hit (wall thickness or clearance).
//! `megaray pick` and the viewers' clicks both come here.

use megaray_base::Ray;
use megaray_trace::Tracer;

/// What a pick found.
#[derive(Clone, Debug, PartialEq)]
pub struct Picked {
    /// The component ([`megaray_scene::Components`]) and its name, when the scene names them.
    pub component: Option<u32>,
    pub name: Option<String>,
    /// The part and the triangle's slot in it.
    pub part: u32,
    pub triangle: u32,
    /// The hit point, from the triangle's corners and barycentrics in f64.
    pub position: [f64; 3],
    /// The unit geometric normal, turned to face the ray.
    pub normal: [f32; 3],
    /// Whether the ray met the triangle's front (its winding's side): entering a closed,
    /// outward-wound part.
    pub front: bool,
    /// From the ray's origin to the hit, in scene units.
    pub distance: f64,
    /// The ray's parameter at the hit.
    pub t: f32,
    /// From the hit to the next surface along the ray, in scene units (the wall's thickness
    /// when the ray entered a part there, the clearance to the next one when it left).
    pub behind: Option<f64>,
}

impl Picked {
    /// Distance between two picked points, in scene units.
    pub fn distance_to(&self, other: &Picked) -> f64 {
        let d: f64 = (0..3).map(|k| (self.position[k] - other.position[k]).powi(2)).sum();
        d.sqrt()
    }

    /// One line for a viewer: name, point, and what lies behind.
    pub fn line(&self) -> String {
        let name = self.name.clone().unwrap_or_else(|| format!("part {} triangle {}", self.part, self.triangle));
        let p = self.position;
        let mut s = format!("{name}  at ({:.4}, {:.4}, {:.4})  distance {:.4}", p[0], p[1], p[2], self.distance);
        if let Some(b) = self.behind {
            s += &format!("  {} {b:.4}", if self.front { "thickness" } else { "clearance" });
        }
        s
    }
}

/// The closest full-detail hit of `ray` and what lies behind it; `None` on a miss.
pub fn pick(tracer: &Tracer<'_>, ray: &Ray) -> Option<Picked> {
    let hit = tracer.intersect(ray)?;
    let scene = tracer.scene();
    let (u, v) = (hit.u as f64, hit.v as f64);
    let c = hit.tri.map(|p| p.map(|x| x as f64));
    let position: [f64; 3] = std::array::from_fn(|k| (1.0 - u - v) * c[0][k] + u * c[1][k] + v * c[2][k]);
    let ng = hit.geometric_normal().normalize_or_zero();
    let front = ng.dot(ray.dir) < 0.0;
    let n = if front { ng } else { -ng };
    let len = ray.dir.length() as f64;
    let o = ray.org.to_array().map(f64::from);
    let distance = (0..3).map(|k| (position[k] - o[k]).powi(2)).sum::<f64>().sqrt();
    // The same ray on past the hit (an offset relative to the distance, so that the hit's
    // own triangle is not met again).
    let step = (hit.t.abs() * 4e-6).max(f32::MIN_POSITIVE);
    let behind_ray = Ray { t_min: hit.t + step, ..*ray };
    let behind = tracer.intersect(&behind_ray).map(|b| (b.t - hit.t) as f64 * len);
    let component = scene.components().of(hit.part, hit.prim);
    Some(Picked {
        component,
        name: component.map(|c| scene.components().name(c).to_string()),
        part: hit.part,
        triangle: hit.prim,
        position,
        normal: n.to_array(),
        front,
        distance,
        t: hit.t,
        behind,
    })
}
