//! The single-ray kernel for incoherent rays, written in assembly (`walk_avx2.s`) with AVX2
//! instructions: it serves AVX2 and AVX-512 machines alike.
//!
//! It walks a new ray through a tracer whose every tile is checked, exactly as
//! [`Tracer::walk`] does (the same box and triangle tests, operation for operation, the same
//! order of visits and pushes, so the same hits bit for bit; the tests compare it with the
//! Rust kernels and the baseline), for closest-hit and any-hit queries. Why by hand: with 16
//! vector and 14 general registers the compiler could not keep what the hot loop needs in
//! registers, chiefly the six plane rows of the ray's octant (it reloaded them from the
//! machine stack at every node and copied them back after every leaf), and it masked and
//! shifted each reference through a 64-bit constant it rematerialized at every node. Here the
//! rows live in six registers as the pool's address plus their offsets, an inner node's
//! offset is two shifts of its reference, the leaf test takes the vector registers the box
//! test holds and reloads them after (ten broadcasts), the ray's constants are made in the
//! kernel from the `Ray` itself (the operations of `RayBox::new` and
//! `RayTri4::with_axis_avx`; a set-up in Rust that passed them in memory cost more than the
//! kernel saved), and one kernel serves rays of every octant. It runs about a fifth fewer
//! instructions per ray than the compiled generic kernel and measured a few percent faster on
//! incoherent rays (docs/PERF.md, "The assembly kernel"). Only new rays that would run the
//! generic kernel come here (incoherent ones): coherent rays keep the octant kernels, which
//! measured faster for them.
//!
//! What the kernel does not do it hands to the Rust driver, as the Rust kernels do: an edge
//! exactly on the ray ([`Event::Exact`]) and a full stack ([`Event::Full`]).

use megaray_base::Ray;
use megaray_scene::format::Node8;

use crate::boxes::{FAR_EPS, TINY, W};
use crate::driver::Scratch;
use crate::tracer::{Entry, Tracer, STACK, TOP};
use crate::tri::{AXES_BYTES, DOMINANT, PERMUTE};
use crate::walk::{Event, Found, Walk};

/// What the assembly kernel reads besides the ray (where to walk) and writes (its
/// outcome). Offsets are given to the assembly as constants (`global_asm!` below), so the two
/// cannot disagree.
#[repr(C, align(64))]
pub(crate) struct AsmRay {
    /// The pool's address ([`Tracer::nodes`]).
    pool: usize,
    /// The thread's stack ([`Scratch::stack`]); out: the pointer past its top entry.
    stack: usize,
    sp: usize,
    /// The stack pointer past which a node's children may not be pushed (at most `STACK - W`
    /// entries up: [`Tracer::asm_stack`]).
    limit: usize,
    /// In: the reference to start from; out, after [`Event::Full`]: the node to visit again.
    root: u64,
    /// Out: the closest hit's distance when `found` (else the ray's end), and that widened.
    t_best: f32,
    t_wide: f32,
    /// Out: 1 when a hit was found (`t_best`, `u`, `v`, `lane`, `unit`).
    found: u32,
    lane: u32,
    /// Out: the hit's block (as [`Found`] has it).
    unit: u64,
    u: f32,
    v: f32,
    /// Out, after [`Event::Exact`]: the leaf's block with an edge on the ray, and its
    /// triangles from there.
    xunit: u64,
    xcount: u32,
}

const _: () = assert!(std::mem::size_of::<AsmRay>() == 128);
// The assembly reads a node's child references at this offset, and entries as 16 bytes.
const _: () = assert!(std::mem::offset_of!(Node8, child) == 192 && STACK == 64 && W == 8);
const _: () = assert!(std::mem::offset_of!(Entry, arr) == 8 && std::mem::offset_of!(Entry, t) == 12);
// The assembly reads a ray's origin, direction, t_min and t_max at 0, 12, 24 and 28.
const _: () = assert!(
    std::mem::offset_of!(Ray, org) == 0
        && std::mem::offset_of!(Ray, dir) == 12
        && std::mem::offset_of!(Ray, t_min) == 24
        && std::mem::offset_of!(Ray, t_max) == 28
);
// Its tables (`.Lmrk_permute`, `.Lmrk_axes`, `.Lmrk_dominant`) are these, written out.
const _: () = {
    let (p, a, d) = (PERMUTE, AXES_BYTES, DOMINANT);
    assert!(p[0][0] == 1 && p[0][1] == 2 && p[0][2] == 0 && p[0][3] == 3);
    assert!(p[1][0] == 2 && p[1][1] == 0 && p[1][2] == 1 && p[1][3] == 3);
    assert!(p[2][0] == 0 && p[2][1] == 1 && p[2][2] == 2 && p[2][3] == 3);
    assert!(a[0][0] == 16 && a[0][1] == 32 && a[0][2] == 0);
    assert!(a[1][0] == 32 && a[1][1] == 0 && a[1][2] == 16);
    assert!(a[2][0] == 0 && a[2][1] == 16 && a[2][2] == 32);
    assert!(d[0] == 2 && d[1] == 2 && d[2] == 2 && d[3] == 0 && d[4] == 1 && d[5] == 2 && d[6] == 1 && d[7] == 0);
};

std::arch::global_asm!(
    include_str!("walk_avx2.s"),
    pool = const std::mem::offset_of!(AsmRay, pool),
    stack = const std::mem::offset_of!(AsmRay, stack),
    sp = const std::mem::offset_of!(AsmRay, sp),
    limit = const std::mem::offset_of!(AsmRay, limit),
    root = const std::mem::offset_of!(AsmRay, root),
    t_best = const std::mem::offset_of!(AsmRay, t_best),
    t_wide = const std::mem::offset_of!(AsmRay, t_wide),
    found = const std::mem::offset_of!(AsmRay, found),
    lane = const std::mem::offset_of!(AsmRay, lane),
    unit = const std::mem::offset_of!(AsmRay, unit),
    u = const std::mem::offset_of!(AsmRay, u),
    v = const std::mem::offset_of!(AsmRay, v),
    xunit = const std::mem::offset_of!(AsmRay, xunit),
    xcount = const std::mem::offset_of!(AsmRay, xcount),
    child = const std::mem::offset_of!(Node8, child),
    far_eps = const FAR_EPS.to_bits(),
    tiny = const TINY.to_bits(),
);

extern "sysv64" {
    /// The closest-hit kernel: 0 when the ray is done, 2 for [`Event::Exact`], 3 for
    /// [`Event::Full`].
    fn megaray_walk_closest(walk: *mut AsmRay, ray: *const Ray) -> u32;
    /// The any-hit kernel: as `megaray_walk_closest`, and 1 when it found a hit.
    fn megaray_walk_any(walk: *mut AsmRay, ray: *const Ray) -> u32;
}

/// Whether this CPU runs the assembly kernel: AVX2 and FMA (as [`Isa::Avx2`]) and
/// the bit instructions it uses (`tzcnt`, `blsr`, `andn`: BMI1; `bzhi`: BMI2).
pub(crate) fn supported() -> bool {
    std::arch::is_x86_feature_detected!("avx2")
        && std::arch::is_x86_feature_detected!("fma")
        && std::arch::is_x86_feature_detected!("bmi1")
        && std::arch::is_x86_feature_detected!("bmi2")
        && std::arch::is_x86_feature_detected!("popcnt")
}

impl Tracer<'_> {
    /// [`Tracer::new_ray`] by the assembly kernel, and what it hands back to the driver.
    ///
    /// # Safety
    /// The CPU must run the kernel ([`supported`]), and every tile must have been checked
    /// ([`Tracer::all_checked`]).
    #[inline(always)]
    pub(crate) unsafe fn new_ray_asm<const ANY: bool>(&self, scratch: &mut Scratch, ray: &Ray) -> Option<Found> {
        let stack = scratch.stack.as_mut_ptr() as usize;
        let mut a = AsmRay {
            pool: self.nodes.as_ptr() as usize,
            stack,
            sp: stack,
            limit: stack + self.asm_stack * std::mem::size_of::<Entry>(),
            root: self.root.r,
            t_best: 0.0,
            t_wide: 0.0,
            found: 0,
            lane: 0,
            unit: 0,
            u: 0.0,
            v: 0.0,
            xunit: 0,
            xcount: 0,
        };
        // SAFETY: the kernel reads the ray, the nodes and blocks that checked references name
        // (all inside the pool, as for the Rust kernels), writes entries only below the
        // stack's `STACK - W` plus the `W - 1` a node's children take (it stops with `Full`
        // before), and the AsmRay; the CPU runs it (the caller's promise).
        let ev = unsafe {
            match ANY {
                true => megaray_walk_any(&mut a, ray),
                false => megaray_walk_closest(&mut a, ray),
            }
        };
        let best =
            (a.found != 0).then_some(Found { t: a.t_best, u: a.u, v: a.v, arr: TOP, lane: a.lane, unit: a.unit });
        match ev {
            0 | 1 => best,
            _ => self.asm_rare::<ANY>(scratch, ray, &a, ev, best),
        }
    }

    /// The walk after the assembly kernel stopped at an event (2 [`Event::Exact`], 3
    /// [`Event::Full`]): on in the driver, with the Rust kernels.
    #[cold]
    #[inline(never)]
    fn asm_rare<const ANY: bool>(
        &self,
        scratch: &mut Scratch,
        ray: &Ray,
        a: &AsmRay,
        ev: u32,
        best: Option<Found>,
    ) -> Option<Found> {
        let mut w = Walk::new(scratch, self.root, ray.t_max);
        w.fresh = false;
        w.sp = (a.sp - a.stack) / std::mem::size_of::<Entry>();
        w.t_best = a.t_best;
        w.best = best;
        let ev = match ev {
            2 => {
                w.next = None;
                Event::Exact { unit: a.xunit, count: a.xcount }
            }
            _ => {
                w.next = Some(Entry { r: a.root, arr: TOP, t: f32::NEG_INFINITY });
                Event::Full
            }
        };
        self.new_ray_rare::<true, ANY>(ray, w, ev)
    }
}
