//! The one place that decides which kernels run. The instruction set ([`Isa`]) is detected
//! once; a tracer is made with a [`Kernels`] choice (the process's, [`Kernels::chosen`], which
//! a front end may set once at start with [`Kernels::configure`]; tests pass their own to
//! [`Tracer::with_kernels`]), from which it takes its tables of kernel functions
//! ([`Tracer::kernel_table`], [`Tracer::new_ray_table`]): one indirect call per ray, no test
//! of a setting on the way.

use megaray_base::Ray;
use std::sync::OnceLock;

use crate::boxes::W;
use crate::driver::Scratch;
use crate::tracer::{Tracer, STACK};
#[cfg(target_arch = "x86_64")]
use crate::walk::{new_ray_avx2, new_ray_avx512, walk_avx2, walk_avx512};
use crate::walk::{walk_baseline, Event, Found, Walk};

/// The instruction sets the kernels are compiled for.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Isa {
    /// Whatever the target guarantees (SSE2 on x86-64).
    Baseline,
    Avx2,
    Avx512,
}

/// What the AVX-512 kernels need: the foundation, 256-bit forms with 32 registers (VL), and
/// AVX2 and FMA beside them.
#[cfg(target_arch = "x86_64")]
fn avx512() -> bool {
    std::arch::is_x86_feature_detected!("avx512f")
        && std::arch::is_x86_feature_detected!("avx512vl")
        && std::arch::is_x86_feature_detected!("avx2")
        && std::arch::is_x86_feature_detected!("fma")
}

impl Isa {
    /// The instruction set named `s` (`avx512`, `avx2` or `baseline`; `sse2` and `scalar`
    /// name the baseline too, as Embree's `isa=` names its own), if this machine can run it;
    /// else why not, in one line.
    pub fn parse(s: &str) -> Result<Isa, String> {
        let isa = match s.trim().to_ascii_lowercase().as_str() {
            "avx512" | "avx-512" => Isa::Avx512,
            "avx2" => Isa::Avx2,
            "baseline" | "sse2" | "scalar" => Isa::Baseline,
            _ => return Err(format!("unknown instruction set {s:?} (use avx512, avx2 or baseline)")),
        };
        match Isa::available().contains(&isa) {
            true => Ok(isa),
            false => Err(format!("this machine cannot run {isa:?} (it has {:?})", Isa::available())),
        }
    }

    /// The best instruction set this machine has (the last of [`Isa::available`]).
    pub fn best() -> Isa {
        *Isa::available().last().expect("the baseline is always available")
    }

    /// Every instruction set this machine can run (the tests compare them all); detected once.
    pub fn available() -> &'static [Isa] {
        static AVAILABLE: OnceLock<Vec<Isa>> = OnceLock::new();
        AVAILABLE.get_or_init(|| {
            let mut v = vec![Isa::Baseline];
            #[cfg(target_arch = "x86_64")]
            {
                if std::arch::is_x86_feature_detected!("avx2") && std::arch::is_x86_feature_detected!("fma") {
                    v.push(Isa::Avx2);
                }
                if avx512() {
                    v.push(Isa::Avx512);
                }
            }
            v
        })
    }
}

/// Which kernels a tracer runs. [`Kernels::best`] is what this machine runs fastest; the
/// other settings exist to compare paths (tests, `MEGARAY_ISA` / `MEGARAY_ASM` in the CLI).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Kernels {
    /// The instruction set of the single-ray and packet kernels (one of [`Isa::available`]).
    pub isa: Isa,
    /// New incoherent rays run the assembly kernel (`asm.rs`) where it can run: x86-64
    /// Linux, AVX2, every tile checked, not a `stats` build.
    pub asm: bool,
    /// The AVX single-ray kernels per octant of ray directions: chosen by the rays'
    /// coherence (`None`), always (`Some(true)`) or never (`Some(false)`).
    pub octants: Option<bool>,
    /// Keep the tile bookkeeping even when every tile is checked
    /// ([`Tracer::skips_tile_checks`] is then false).
    pub tile_checks: bool,
    /// How many stack entries the assembly kernel may have below a node whose children it
    /// pushes (at most `STACK - 8`; fewer make it hand its walk to the driver for room).
    pub asm_stack: usize,
}

/// The process's choice ([`Kernels::configure`]).
static CHOSEN: OnceLock<Kernels> = OnceLock::new();

impl Kernels {
    /// The fastest kernels this machine has.
    pub fn best() -> Kernels {
        Kernels { isa: Isa::best(), asm: true, octants: None, tile_checks: false, asm_stack: STACK - W }
    }

    /// Sets the kernels every [`Tracer::new`] of this process runs, once, before the first
    /// tracer (a front end, from its settings). Fails if a choice was made or used already,
    /// or if `k.isa` is not available here.
    pub fn configure(k: Kernels) -> Result<(), String> {
        if !Isa::available().contains(&k.isa) {
            return Err(format!("this machine cannot run {:?} (it has {:?})", k.isa, Isa::available()));
        }
        CHOSEN.set(k).map_err(|_| "the kernels were chosen already (configure them before the first tracer)".into())
    }

    /// The kernels [`Tracer::new`] runs: as configured, else [`Kernels::best`].
    pub fn chosen() -> Kernels {
        *CHOSEN.get_or_init(Kernels::best)
    }
}

/// A single-ray kernel: [`Tracer::walk`] compiled for one instruction set, query kind, tile
/// bookkeeping and kernel number. Unsafe: the AVX ones must only run where the CPU has the
/// instructions, which [`Tracer::kernel_table`] sees to.
pub(crate) type Kernel = for<'a, 'b, 'c, 'd> unsafe fn(&'a Tracer<'b>, &'c mut Walk<'d>, &Ray) -> Event;

/// A kernel for a new ray ([`Tracer::new_ray`]): what [`Kernel`] is for a walk, from the
/// thread's scratch memory to the closest (or any) hit. Unsafe as [`Kernel`] is.
pub(crate) type NewRay = for<'a, 'b, 'c> unsafe fn(&'a Tracer<'b>, &'c mut Scratch, &Ray) -> Option<Found>;

/// The generic kernel's number ([`Tracer::walk_on`]; octants' are `0..8`).
pub(crate) const GENERIC: usize = 8;

/// A row of a kernel table: `$f` with the given leading const arguments, then each kernel
/// number (the eight octants, then [`GENERIC`]), as function pointers of type `$ty`.
#[cfg_attr(not(target_arch = "x86_64"), allow(unused_macros))]
macro_rules! kernel_row {
    ($f:ident, $ty:ty, $($arg:literal),+) => {
        [
            $f::<$($arg,)+ 0> as $ty,
            $f::<$($arg,)+ 1> as $ty,
            $f::<$($arg,)+ 2> as $ty,
            $f::<$($arg,)+ 3> as $ty,
            $f::<$($arg,)+ 4> as $ty,
            $f::<$($arg,)+ 5> as $ty,
            $f::<$($arg,)+ 6> as $ty,
            $f::<$($arg,)+ 7> as $ty,
            $f::<$($arg,)+ GENERIC> as $ty,
        ]
    };
}

/// Kernels per query kind: eight octant ones and the generic one ([`Tracer::walk_on`]).
pub(crate) const KERNELS: usize = GENERIC + 1;

impl<'s> Tracer<'s> {
    /// Whether new rays run the assembly kernel: asked for (`k.asm`), on AVX2 or AVX-512 (its
    /// instructions are AVX2's; for incoherent rays it is faster than the compiled AVX-512
    /// kernel too: docs/PERF.md, "The assembly kernel"), where every tile is checked (`all`).
    pub(crate) fn asm_kernel(k: &Kernels, all: bool) -> bool {
        #[cfg(all(target_arch = "x86_64", target_os = "linux"))]
        if k.asm && all && matches!(k.isa, Isa::Avx2 | Isa::Avx512) && !cfg!(feature = "stats") {
            return crate::asm::supported();
        }
        let _ = (k, all);
        false
    }

    /// The new-ray kernels for `isa` where every tile is checked (`all`), else `None`
    /// ([`Tracer::new_ray`]).
    pub(crate) fn new_ray_table(isa: Isa, all: bool) -> Option<[[NewRay; KERNELS]; 2]> {
        if !all {
            return None;
        }
        #[cfg(target_arch = "x86_64")]
        match isa {
            Isa::Avx512 => {
                return Some([kernel_row!(new_ray_avx512, NewRay, false), kernel_row!(new_ray_avx512, NewRay, true)])
            }
            Isa::Avx2 => {
                return Some([kernel_row!(new_ray_avx2, NewRay, false), kernel_row!(new_ray_avx2, NewRay, true)])
            }
            _ => {}
        }
        let _ = isa;
        None
    }

    /// The kernels for `isa`, with tile bookkeeping unless `all` tiles are checked
    /// ([`Tracer::kernels`]).
    pub(crate) fn kernel_table(isa: Isa, all: bool) -> [[Kernel; KERNELS]; 2] {
        #[cfg(target_arch = "x86_64")]
        match (isa, all) {
            (Isa::Avx512, true) => {
                return [kernel_row!(walk_avx512, Kernel, false, true), kernel_row!(walk_avx512, Kernel, true, true)]
            }
            (Isa::Avx512, false) => {
                return [kernel_row!(walk_avx512, Kernel, false, false), kernel_row!(walk_avx512, Kernel, true, false)]
            }
            (Isa::Avx2, true) => {
                return [kernel_row!(walk_avx2, Kernel, false, true), kernel_row!(walk_avx2, Kernel, true, true)]
            }
            (Isa::Avx2, false) => {
                return [kernel_row!(walk_avx2, Kernel, false, false), kernel_row!(walk_avx2, Kernel, true, false)]
            }
            _ => {}
        }
        let _ = isa;
        match all {
            true => {
                [[walk_baseline::<false, true> as Kernel; KERNELS], [walk_baseline::<true, true> as Kernel; KERNELS]]
            }
            false => {
                [[walk_baseline::<false, false> as Kernel; KERNELS], [walk_baseline::<true, false> as Kernel; KERNELS]]
            }
        }
    }
}
