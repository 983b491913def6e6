//! Small lane loops (16 camera rays, their box test; the accumulator's add in
//! `megaray-render`, through the exported macros) compiled for the widest vector
//! instructions the machine has, chosen at run time: the same Rust code inlined into a copy
//! per instruction set ([`compiled_for!`]) and the copy picked per call ([`dispatch!`], a
//! cached feature test). The copies compute the same bits: only the vector width differs
//! (no fused multiply-add is enabled, and Rust never contracts on its own). Each caller's
//! tests compare the dispatched result with the baseline's.

#[doc(hidden)]
#[macro_export]
/// Defines `$wide512` and `$wide2`: `$body` (a method of `Self` taking `&self` and the
/// arguments, or with `fn`, a function) compiled for AVX-512 and for AVX2. x86-64 only.
macro_rules! compiled_for {
    ($wide512:ident, $wide2:ident, fn $body:ident($($arg:ident: $ty:ty),*)) => {
        #[cfg(target_arch = "x86_64")]
        #[target_feature(enable = "avx512f,avx2")]
        fn $wide512($($arg: $ty),*) {
            $body($($arg),*)
        }
        #[cfg(target_arch = "x86_64")]
        #[target_feature(enable = "avx2")]
        fn $wide2($($arg: $ty),*) {
            $body($($arg),*)
        }
    };
    ($wide512:ident, $wide2:ident, $body:ident(&self $(, $arg:ident: $ty:ty)*) -> $ret:ty) => {
        #[cfg(target_arch = "x86_64")]
        #[target_feature(enable = "avx512f,avx2")]
        fn $wide512(&self $(, $arg: $ty)*) -> $ret {
            self.$body($($arg),*)
        }
        #[cfg(target_arch = "x86_64")]
        #[target_feature(enable = "avx2")]
        fn $wide2(&self $(, $arg: $ty)*) -> $ret {
            self.$body($($arg),*)
        }
    };
}

#[doc(hidden)]
#[macro_export]
/// `$wide512(self, ..)` where the machine has AVX-512, `$wide2(self, ..)` where it has AVX2,
/// else `self.body(args)` (or, without `self.`, the function `body(args)`). Returns from the
/// enclosing function in the first two cases.
macro_rules! dispatch {
    ($body:ident($($arg:expr),*), $wide512:path, $wide2:path) => {{
        #[cfg(target_arch = "x86_64")]
        {
            if std::arch::is_x86_feature_detected!("avx512f") {
                // SAFETY: the CPU has AVX-512F and AVX2 (tested just now); the function is
                // safe Rust compiled for them.
                return unsafe { $wide512($($arg),*) };
            }
            if std::arch::is_x86_feature_detected!("avx2") {
                // SAFETY: the CPU has AVX2 (tested just now), as above.
                return unsafe { $wide2($($arg),*) };
            }
        }
        $body($($arg),*)
    }};
    ($self:ident.$body:ident($($arg:expr),*), $wide512:path, $wide2:path) => {{
        #[cfg(target_arch = "x86_64")]
        {
            if std::arch::is_x86_feature_detected!("avx512f") {
                // SAFETY: the CPU has AVX-512F and AVX2 (tested just now); the function is
                // safe Rust compiled for them.
                return unsafe { $wide512($self $(, $arg)*) };
            }
            if std::arch::is_x86_feature_detected!("avx2") {
                // SAFETY: the CPU has AVX2 (tested just now), as above.
                return unsafe { $wide2($self $(, $arg)*) };
            }
        }
        $self.$body($($arg),*)
    }};
}

pub(crate) use {compiled_for, dispatch};
