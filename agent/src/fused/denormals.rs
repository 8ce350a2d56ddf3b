//! Flush-to-zero for the fused update: subnormal floats (|x| < 1.2e-38) cost x86 cores a microcode
//! assist per instruction that reads or writes one, a hundred cycles or more instead of a few.
//! Training makes them: the Adam moments of weights whose gradient is (nearly) always zero (the
//! weights out of dead ReLU units, mostly in the critics' and embedding's second layers) decay
//! geometrically through the subnormal range. Checkpoints of 20-minute Ant runs held 13,000-24,000
//! subnormal values, all in Adam moments, and in those runs the learner's updates/s fell by a
//! quarter as they accumulated. With FTZ and DAZ set, the
//! result of an operation that would be subnormal is 0 and a subnormal input reads as 0: values
//! below f32's normal range, eight orders of magnitude below any gradient the update uses.
//!
//! [`FlushDenormals`] sets both bits of this thread's MXCSR for its lifetime and restores the
//! caller's on drop, so only the fused update's own arithmetic is affected. Elsewhere than on
//! x86-64 it does nothing.

/// This thread's SSE control word with FTZ and DAZ set, until dropped.
#[derive(Debug)]
pub(crate) struct FlushDenormals {
    #[cfg(target_arch = "x86_64")]
    saved: u32,
}

/// MXCSR bit 15: flush subnormal results to zero.
#[cfg(target_arch = "x86_64")]
const FLUSH_TO_ZERO: u32 = 1 << 15;
/// MXCSR bit 6: treat subnormal inputs as zero.
#[cfg(target_arch = "x86_64")]
const DENORMALS_ARE_ZERO: u32 = 1 << 6;

#[cfg(target_arch = "x86_64")]
fn read_mxcsr() -> u32 {
    let mut csr = 0u32;
    // SAFETY: stmxcsr writes the 4-byte control word to a valid, aligned local.
    unsafe { std::arch::asm!("stmxcsr [{}]", in(reg) &mut csr, options(nostack, preserves_flags)) };
    csr
}

#[cfg(target_arch = "x86_64")]
fn write_mxcsr(csr: u32) {
    // SAFETY: ldmxcsr loads a control word read from the register with at most FTZ and DAZ added,
    // both defined on every x86-64 core; it changes the rounding of subnormals only.
    unsafe { std::arch::asm!("ldmxcsr [{}]", in(reg) &csr, options(nostack, readonly, preserves_flags)) };
}

impl FlushDenormals {
    /// Sets FTZ and DAZ on this thread.
    pub(crate) fn new() -> Self {
        #[cfg(target_arch = "x86_64")]
        {
            let saved = read_mxcsr();
            write_mxcsr(saved | FLUSH_TO_ZERO | DENORMALS_ARE_ZERO);
            Self { saved }
        }
        #[cfg(not(target_arch = "x86_64"))]
        Self {}
    }
}

impl Drop for FlushDenormals {
    fn drop(&mut self) {
        #[cfg(target_arch = "x86_64")]
        write_mxcsr(self.saved);
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Computed at run time so that the compiler cannot fold it.
    fn halve(x: f32) -> f32 {
        std::hint::black_box(x) * std::hint::black_box(0.5)
    }

    #[test]
    fn subnormal_results_are_zero_inside_the_guard_and_not_after() {
        let tiny = f32::MIN_POSITIVE; // the smallest normal f32; half of it is subnormal
        assert!(halve(tiny) > 0.0);
        {
            let _flush = FlushDenormals::new();
            #[cfg(target_arch = "x86_64")]
            assert_eq!(halve(tiny), 0.0);
        }
        assert!(halve(tiny) > 0.0, "the caller's mode is restored");
        assert_eq!(halve(tiny).to_bits(), (tiny / 2.0).to_bits());
    }
}
