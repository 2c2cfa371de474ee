//! Run-time choice of vector instructions: the wheel is built for baseline x86-64 and must
//! run on any of it, while the numerical loops are several times faster on the widest vector
//! unit the CPU has.

/// Defines `fn NAME(args) -> R` that runs `BODY(args)` (an `#[inline(always)]` function with
/// the same arguments) compiled for AVX-512, for AVX2 with FMA, or for baseline x86-64 —
/// the widest the CPU offers, detected at each call (the detection is cached). The three
/// compilations perform the same operations in the same order (Rust never contracts
/// `a * b + c` into a fused multiply-add), so results do not depend on the CPU.
macro_rules! widest_vectors {
    ($(#[$meta:meta])* $vis:vis fn $name:ident($($arg:ident: $ty:ty),* $(,)?) $(-> $ret:ty)? = $body:path;) => {
        $(#[$meta])*
        $vis fn $name($($arg: $ty),*) $(-> $ret)? {
            #[cfg(target_arch = "x86_64")]
            {
                #[target_feature(enable = "avx512f")]
                unsafe fn avx512($($arg: $ty),*) $(-> $ret)? {
                    $body($($arg),*)
                }
                #[target_feature(enable = "avx2,fma")]
                unsafe fn avx2($($arg: $ty),*) $(-> $ret)? {
                    $body($($arg),*)
                }
                if std::arch::is_x86_feature_detected!("avx512f") {
                    // SAFETY: the CPU supports the features the function is compiled for.
                    return unsafe { avx512($($arg),*) };
                }
                if std::arch::is_x86_feature_detected!("avx2")
                    && std::arch::is_x86_feature_detected!("fma")
                {
                    // SAFETY: as above.
                    return unsafe { avx2($($arg),*) };
                }
            }
            $body($($arg),*)
        }
    };
}

pub(crate) use widest_vectors;
