//! The fused step's hot loops (the matrix kernel, the softplus layer) compiled for the
//! widest vector instructions the CPU has, chosen at run time.
//!
//! The crate is compiled for the baseline of its target (on `x86_64`: SSE2, four `f32`
//! lanes). [`dispatch`] runs a loop through `pulp`, which compiles it again for AVX2 (eight
//! lanes) and picks the build the CPU runs. Both builds do the same IEEE operations in the
//! same order — Rust never fuses a multiply and an add unless asked — so a run gives the
//! same numbers whichever build ran.

use std::sync::OnceLock;

/// Runs `work` in the widest build this CPU supports. Its `with_simd` and what that calls
/// must be `#[inline(always)]` to be compiled into that build. `GBC_PORTABLE=1` forces the
/// baseline build (to compare the two).
#[inline(always)]
pub fn dispatch<Work: pulp::WithSimd>(work: Work) -> Work::Output {
    static ARCH: OnceLock<Option<pulp::Arch>> = OnceLock::new();
    let arch = ARCH.get_or_init(|| {
        std::env::var_os("GBC_PORTABLE")
            .is_none()
            .then(pulp::Arch::new)
    });
    match arch {
        Some(arch) => arch.dispatch(work),
        None => work.with_simd(pulp::Scalar::new()),
    }
}
