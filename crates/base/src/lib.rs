//! # megaray-base: the foundations every other megaray crate stands on
//!
//! Nothing here knows about scenes or images. It holds:
//! - [`Aabb`]: axis-aligned bounding boxes (build and trace both use them);
//! - [`Affine`]: the 3x4 transforms that place instances;
//! - [`Camera`]: the pinhole camera and the benchmark framings (rays through pixels);
//! - [`Ray`] and [`intersect_triangle`]: the scalar, watertight ray-triangle test
//!   (Woop, Benthin and Wald 2013) that is the reference every faster kernel is tested against;
//! - [`Progress`]: how long-running library code reports progress without knowing about terminals;
//! - [`parse_size`]: `64K`, `1G`, `1.5GiB` style sizes, for memory budgets on the command line;
//! - [`process_memory`]: the process's resident memory as the kernel counts it (file-backed,
//!   anonymous, peak), which the pager's statistics report beside its own count;
//! - [`temp`]: how outputs are written (a temporary name, then a rename) and how temporaries left
//!   by killed processes are cleaned up.
//!
//! ```
//! use megaray_base::{Ray, intersect_triangle, Vec3};
//! let ray = Ray::new(Vec3::new(0.25, 0.25, -1.0), Vec3::Z);
//! let hit = intersect_triangle(&ray, [Vec3::ZERO, Vec3::X, Vec3::Y], f32::INFINITY).unwrap();
//! assert!((hit.t - 1.0).abs() < 1e-6);
//! ```

mod aabb;
mod affine;
mod camera;
mod progress;
mod ray;
mod size;
pub mod temp;
mod wide;

pub use aabb::Aabb;
pub use affine::Affine;
pub use camera::{Camera, CLOSE_OFFSET, DEFAULT_OFFSET};
pub use glam::Vec3;
pub use progress::{NoProgress, Progress};
pub use ray::{intersect_triangle, t_start, Ray, Rays16, TriHit, WatertightRay};
pub use size::{format_size, parse_size};

/// Most levels of instancing a scene may nest (groups within groups, glTF nodes within nodes,
/// pbrt objects placing objects): the tracer walks them recursively, under a kilobyte of a
/// thread's stack a level, so deeper scenes are refused with one line where they are read.
pub const MAX_NESTING: u32 = 256;

/// Starts loading the cache line that holds `x` (a hint: it never faults and changes nothing
/// the program can see; a no-op off x86-64). For passes that gather from big arrays in an
/// order known ahead, so that their misses overlap instead of queueing.
#[inline(always)]
pub fn prefetch<T>(x: &T) {
    prefetch_addr((x as *const T).cast::<u8>());
}

/// [`prefetch`] of whatever cache line holds address `p`, which need not point into
/// anything the program owns (a traversal computes the addresses of children it may visit).
#[inline(always)]
pub fn prefetch_addr(p: *const u8) {
    #[cfg(target_arch = "x86_64")]
    // SAFETY: a prefetch is a hint with no architectural effect: it never faults, whatever
    // the address, and reads nothing into the program.
    unsafe {
        std::arch::x86_64::_mm_prefetch::<{ std::arch::x86_64::_MM_HINT_T0 }>(p.cast::<i8>())
    };
    #[cfg(not(target_arch = "x86_64"))]
    let _ = p;
}

/// Colour pixels seen as atomics, for threads that each write a disjoint set of them (a
/// frame's interleaved pixel groups, written where they finish): a relaxed store is a plain
/// store, and the `&mut` borrow held meanwhile keeps every other access out.
pub fn pixels_as_atomic(px: &mut [[f32; 3]]) -> &[[std::sync::atomic::AtomicU32; 3]] {
    use std::sync::atomic::AtomicU32;
    const _: () = assert!(std::mem::size_of::<AtomicU32>() == 4 && std::mem::align_of::<AtomicU32>() == 4);
    // SAFETY: a byte cast: `AtomicU32` has the size and alignment of `u32`, hence of `f32`
    // (asserted above), and any bits are a valid `u32`. The exclusive borrow of `px` lasts
    // as long as the result, so no access but through the atomics can happen meanwhile.
    unsafe { std::slice::from_raw_parts(px.as_mut_ptr().cast::<[AtomicU32; 3]>(), px.len()) }
}

/// The lowbias32 integer hash: deterministic per-pixel random numbers (the Embree peer
/// harness uses the same one, so ray sets can be compared).
#[inline]
pub fn hash32(mut x: u32) -> u32 {
    x ^= x >> 16;
    x = x.wrapping_mul(0x7feb_352d);
    x ^= x >> 15;
    x = x.wrapping_mul(0x846c_a68b);
    x ^= x >> 16;
    x
}

/// A hash as a float in `[0, 1)` (its top 24 bits).
#[inline]
pub fn u01(h: u32) -> f32 {
    (h >> 8) as f32 * (1.0 / 16_777_216.0)
}

/// This process's resident memory as the kernel counts it (`/proc/self/status`, Linux).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct ProcessMemory {
    /// Pages of mapped files (`RssFile`).
    pub file: u64,
    /// Anonymous pages (`RssAnon`): heap, stacks, and a pager's owned scene region.
    pub anon: u64,
    /// The peak of the whole resident set (`VmHWM`).
    pub peak: u64,
}

/// This process's resident memory now, where the system reports it (Linux); `None` elsewhere.
pub fn process_memory() -> Option<ProcessMemory> {
    let s = std::fs::read_to_string("/proc/self/status").ok()?;
    let kb = |key: &str| -> Option<u64> {
        let line = s.lines().find(|l| l.starts_with(key))?;
        Some(line.split_whitespace().nth(1)?.parse::<u64>().ok()? * 1024)
    };
    Some(ProcessMemory { file: kb("RssFile:")?, anon: kb("RssAnon:")?, peak: kb("VmHWM:")? })
}

/// This process's peak resident set size in bytes (`VmHWM` of `/proc/self/status`), where the
/// system reports it (Linux); `None` elsewhere.
pub fn peak_rss() -> Option<u64> {
    process_memory().map(|m| m.peak)
}

/// A triangle's three corners as plain arrays, the form triangles take on disk and in streams.
pub type TriVerts = [[f32; 3]; 3];

/// `true` when every coordinate of the triangle is finite (neither NaN nor infinite).
#[inline]
pub fn tri_is_finite(t: &TriVerts) -> bool {
    t.iter().flatten().all(|c| c.is_finite())
}

/// `true` when the triangle has (numerically) zero area: such triangles can never be hit
/// by the watertight test and are dropped by the builder (and counted).
#[inline]
pub fn tri_is_degenerate(t: &TriVerts) -> bool {
    let a = Vec3::from(t[0]);
    let b = Vec3::from(t[1]);
    let c = Vec3::from(t[2]);
    let n = (b - a).cross(c - a);
    n.length_squared() == 0.0 || !n.is_finite()
}
