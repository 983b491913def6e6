use crate::{plant, GenError};
use std::fmt;
use std::str::FromStr;

/// Which model to generate. Parsed from the command line's spec strings (see [`FromStr`]).
#[derive(Clone, Debug, PartialEq, Eq, Hash)]
pub enum GenSpec {
    /// `grid:N`: the peer's height field over `x, z ∈ [-1, 1]`, `N × N` cells,
    /// `(N + 1)²` vertices and `2N²` triangles.
    Grid {
        /// Cells along each side, `1..=65534`.
        n: u32,
    },
    /// `sphereflake:L[:S]`: the peer's Haines sphere flake, `Σ 9^i` (`i = 0..=L`) UV spheres of
    /// `S` latitude bands and `2S` longitude segments (`4S(S − 1)` triangles each).
    Sphereflake {
        /// Recursion levels `L`, `0..=10` (`L = 4`: 7381 spheres).
        levels: u32,
        /// Latitude bands `S` per sphere, `2..=1000` (the peer's default is 12).
        bands: u32,
    },
    /// `plant:T[:SEED]`: a CAD-like industrial plant of about `T` triangles (within 2% for
    /// `T ≥ 10k`), made of thousands of pipes, tanks, beams, stairs, gratings, valves and cables.
    Plant {
        /// The triangle count asked for (`counts()` gives the exact count generated).
        tris: u64,
        /// Seed of the layout; the same `tris` and `seed` give the same model, byte for byte.
        seed: u64,
    },
}

/// Default latitude bands of a sphere flake (the peer's).
const DEFAULT_BANDS: u32 = 12;
/// Default plant seed.
const DEFAULT_SEED: u64 = 1;
/// Smallest plant, in triangles.
pub(crate) const PLANT_MIN: u64 = 1000;
/// Largest plant, in triangles.
pub(crate) const PLANT_MAX: u64 = 100_000_000_000;

impl FromStr for GenSpec {
    type Err = GenError;

    /// Parses `grid:1000`, `sphereflake:4`, `sphereflake:4:12`, `plant:100M`, `plant:2.5M`,
    /// `plant:1G`, `plant:300k`, `plant:5000`, `plant:100M:7` (seed 7; the default seed is 1).
    /// Suffixes `k`, `M`, `G` (either case) multiply by 10³, 10⁶, 10⁹.
    fn from_str(s: &str) -> Result<Self, Self::Err> {
        let parts: Vec<&str> = s.trim().split(':').map(str::trim).collect();
        let err = |what: &str| GenError::spec(s, what);
        let kind = parts[0].to_ascii_lowercase();
        match kind.as_str() {
            "grid" => {
                let [_, n] = parts[..] else {
                    return Err(err("expected grid:N (N cells a side, e.g. grid:1000)"));
                };
                let n = parse_int(n).ok_or_else(|| err("not a number of cells"))?;
                if !(1..=65534).contains(&n) {
                    return Err(err("the grid size must be 1 to 65534 cells"));
                }
                Ok(GenSpec::Grid { n: n as u32 })
            }
            "sphereflake" => {
                let (levels, bands) = match parts[..] {
                    [_, l] => (l, None),
                    [_, l, b] => (l, Some(b)),
                    _ => return Err(err("expected sphereflake:LEVELS[:BANDS] (e.g. sphereflake:4)")),
                };
                let levels = parse_int(levels).ok_or_else(|| err("not a number of levels"))?;
                if levels > 10 {
                    return Err(err("at most 10 levels"));
                }
                let bands = match bands {
                    None => DEFAULT_BANDS as u64,
                    Some(b) => parse_int(b).ok_or_else(|| err("not a number of bands"))?,
                };
                if !(2..=1000).contains(&bands) {
                    return Err(err("a sphere needs 2 to 1000 latitude bands"));
                }
                Ok(GenSpec::Sphereflake { levels: levels as u32, bands: bands as u32 })
            }
            "plant" => {
                let (tris, seed) = match parts[..] {
                    [_, t] => (t, None),
                    [_, t, s] => (t, Some(s)),
                    _ => return Err(err("expected plant:TRIANGLES[:SEED] (e.g. plant:100M)")),
                };
                let tris = parse_count(tris).ok_or_else(|| err("not a triangle count"))?;
                if !(PLANT_MIN..=PLANT_MAX).contains(&tris) {
                    return Err(err("a plant has 1k to 100G triangles"));
                }
                let seed = match seed {
                    None => DEFAULT_SEED,
                    Some(x) => parse_int(x).ok_or_else(|| err("not a seed (an unsigned integer)"))?,
                };
                Ok(GenSpec::Plant { tris, seed })
            }
            _ => Err(err("unknown model (use grid:N, sphereflake:L[:S] or plant:T[:SEED])")),
        }
    }
}

/// A plain unsigned integer.
fn parse_int(s: &str) -> Option<u64> {
    if s.is_empty() || !s.bytes().all(|b| b.is_ascii_digit()) {
        return None;
    }
    s.parse().ok()
}

/// `300k`, `2.5M`, `1G`, `5000`: a decimal number with an optional k/M/G suffix, rounded to an
/// integer.
fn parse_count(s: &str) -> Option<u64> {
    let (num, mult) = match s.as_bytes().last()? {
        b'k' | b'K' => (&s[..s.len() - 1], 1e3),
        b'm' | b'M' => (&s[..s.len() - 1], 1e6),
        b'g' | b'G' => (&s[..s.len() - 1], 1e9),
        _ => (s, 1.0),
    };
    let digits = num.bytes().filter(u8::is_ascii_digit).count();
    let dots = num.bytes().filter(|&b| b == b'.').count();
    if digits == 0 || dots > 1 || digits + dots != num.len() {
        return None;
    }
    let v = num.parse::<f64>().ok()? * mult;
    (v.is_finite() && v < 1e18).then(|| v.round() as u64)
}

/// `2000000` → `2M`, `2500000` → `2500k`, `1234` → `1234`.
fn format_count(t: u64) -> String {
    if t > 0 && t % 1_000_000_000 == 0 {
        format!("{}G", t / 1_000_000_000)
    } else if t > 0 && t % 1_000_000 == 0 {
        format!("{}M", t / 1_000_000)
    } else if t > 0 && t % 1000 == 0 {
        format!("{}k", t / 1000)
    } else {
        t.to_string()
    }
}

impl GenSpec {
    /// The same spec with another seed (only plants have one; others are returned unchanged).
    pub fn with_seed(self, seed: u64) -> Self {
        match self {
            GenSpec::Plant { tris, .. } => GenSpec::Plant { tris, seed },
            other => other,
        }
    }

    /// The canonical spec string, which parses back to the same spec: `grid:1000`,
    /// `sphereflake:4` (bands left out when 12), `plant:2500k` (seed left out when 1),
    /// `plant:100M:7`.
    pub fn name(&self) -> String {
        match *self {
            GenSpec::Grid { n } => format!("grid:{n}"),
            GenSpec::Sphereflake { levels, bands } if bands == DEFAULT_BANDS => {
                format!("sphereflake:{levels}")
            }
            GenSpec::Sphereflake { levels, bands } => format!("sphereflake:{levels}:{bands}"),
            GenSpec::Plant { tris, seed } if seed == DEFAULT_SEED => {
                format!("plant:{}", format_count(tris))
            }
            GenSpec::Plant { tris, seed } => format!("plant:{}:{seed}", format_count(tris)),
        }
    }

    /// The exact `(vertices, triangles)` that [`generate`](crate::generate) will emit, computed
    /// without making any geometry (for a plant, by running its layout, which takes a few
    /// milliseconds per million triangles).
    pub fn counts(&self) -> (u64, u64) {
        match *self {
            GenSpec::Grid { n } => {
                let n = n as u64;
                ((n + 1) * (n + 1), 2 * n * n)
            }
            GenSpec::Sphereflake { levels, bands } => {
                let spheres: u64 = (0..=levels).map(|i| 9u64.pow(i)).sum();
                let s = bands as u64;
                (spheres * (2 + (s - 1) * 2 * s), spheres * 4 * s * (s - 1))
            }
            GenSpec::Plant { tris, seed } => plant::counts(tris, seed),
        }
    }
}

impl fmt::Display for GenSpec {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(&self.name())
    }
}
