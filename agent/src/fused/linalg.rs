//! Bounds-checked strided views over `f32` buffers and the one matrix product the fused update
//! needs, on the `gemm` crate (the same kernels candle's CPU matmul calls).
//!
//! A view addresses element (i, j) at `data[i * rs + j * cs]`, so a transpose is a swap of the
//! strides and a column block of a wider row-major matrix is an offset: the forward product
//! X W^T, the input gradient dY W and the weight gradient dY^T X all run on the stored `[out, in]`
//! weights and row-major activations without copies.

use gemm::Parallelism;

/// Largest index a `rows x cols` view with strides (`rs`, `cs`) touches, plus one.
fn extent(rows: usize, cols: usize, rs: usize, cs: usize) -> usize {
    if rows == 0 || cols == 0 { 0 } else { (rows - 1) * rs + (cols - 1) * cs + 1 }
}

/// A read-only strided matrix view; constructors check that every element is inside `data`.
#[derive(Clone, Copy, Debug)]
pub(crate) struct Mat<'a> {
    data: &'a [f32],
    rows: usize,
    cols: usize,
    rs: usize,
    cs: usize,
}

impl<'a> Mat<'a> {
    /// `rows x cols`, row-major, consecutive rows `stride` apart.
    pub(crate) fn strided(data: &'a [f32], rows: usize, cols: usize, stride: usize) -> Self {
        assert!(cols <= stride || rows <= 1, "row stride {stride} below width {cols}");
        assert!(
            extent(rows, cols, stride, 1) <= data.len(),
            "view {rows}x{cols}/{stride} exceeds {}",
            data.len()
        );
        Self { data, rows, cols, rs: stride, cs: 1 }
    }

    /// A dense row-major `rows x cols` matrix at the start of `data`.
    pub(crate) fn dense(data: &'a [f32], rows: usize, cols: usize) -> Self {
        Self::strided(data, rows, cols, cols)
    }

    /// The transpose (no data moves).
    pub(crate) fn t(self) -> Self {
        Self { rows: self.cols, cols: self.rows, rs: self.cs, cs: self.rs, ..self }
    }

    /// Columns `from .. from + n`.
    pub(crate) fn columns(self, from: usize, n: usize) -> Self {
        assert!(from + n <= self.cols, "columns {from}+{n} of {}", self.cols);
        let offset = if n == 0 { 0 } else { from * self.cs };
        Self { data: &self.data[offset..], cols: n, ..self }
    }

    /// The first `n` rows.
    pub(crate) fn top(self, n: usize) -> Self {
        assert!(n <= self.rows, "top {n} of {} rows", self.rows);
        Self { rows: n, ..self }
    }

    /// Number of rows.
    pub(crate) fn rows(&self) -> usize {
        self.rows
    }

    /// Number of columns.
    pub(crate) fn cols(&self) -> usize {
        self.cols
    }

    /// All elements as one slice, when rows follow each other without gaps (row-major, dense).
    #[inline(always)]
    pub(crate) fn contiguous(&self) -> Option<&'a [f32]> {
        (self.cs == 1 && (self.rs == self.cols || self.rows <= 1))
            .then(|| &self.data[..self.rows * self.cols])
    }

    /// Row `i` of a view with unit column stride.
    pub(crate) fn row(&self, i: usize) -> &'a [f32] {
        assert!(
            self.cs == 1 && i < self.rows,
            "row {i} of a {}-row view with column stride {}",
            self.rows,
            self.cs
        );
        &self.data[i * self.rs..i * self.rs + self.cols]
    }
}

/// A mutable row-major view with unit column stride (every destination in this module is one).
#[derive(Debug)]
pub(crate) struct MatMut<'a> {
    data: &'a mut [f32],
    rows: usize,
    cols: usize,
    rs: usize,
}

impl<'a> MatMut<'a> {
    /// `rows x cols`, row-major, consecutive rows `stride` apart.
    pub(crate) fn strided(data: &'a mut [f32], rows: usize, cols: usize, stride: usize) -> Self {
        assert!(cols <= stride || rows <= 1, "row stride {stride} below width {cols}");
        assert!(
            extent(rows, cols, stride, 1) <= data.len(),
            "view {rows}x{cols}/{stride} exceeds {}",
            data.len()
        );
        Self { data, rows, cols, rs: stride }
    }

    /// A dense row-major `rows x cols` matrix at the start of `data`.
    pub(crate) fn dense(data: &'a mut [f32], rows: usize, cols: usize) -> Self {
        Self::strided(data, rows, cols, cols)
    }

    /// Columns `from .. from + n`, consuming the view.
    pub(crate) fn columns(self, from: usize, n: usize) -> Self {
        assert!(from + n <= self.cols, "columns {from}+{n} of {}", self.cols);
        let offset = if n == 0 { 0 } else { from };
        Self { data: &mut self.data[offset..], cols: n, ..self }
    }

    /// Number of rows.
    pub(crate) fn rows(&self) -> usize {
        self.rows
    }

    /// All elements as one slice, when rows follow each other without gaps (row-major, dense).
    #[inline(always)]
    pub(crate) fn contiguous_mut(&mut self) -> Option<&mut [f32]> {
        (self.rs == self.cols || self.rows <= 1).then(|| &mut self.data[..self.rows * self.cols])
    }

    /// Row `i`, mutable.
    pub(crate) fn row_mut(&mut self, i: usize) -> &mut [f32] {
        assert!(i < self.rows, "row {i} of {}", self.rows);
        &mut self.data[i * self.rs..i * self.rs + self.cols]
    }

    /// A read-only view of the same elements.
    pub(crate) fn as_mat(&self) -> Mat<'_> {
        Mat { data: self.data, rows: self.rows, cols: self.cols, rs: self.rs, cs: 1 }
    }
}

/// A loop nest to compile for the widest vector instructions the CPU has. `run` must be
/// `#[inline(always)]` (as must everything it calls that should vectorise): it is then inlined
/// into pulp's AVX-512, AVX2 + FMA and baseline entry points, each compiled with its own target
/// features. (A closure would not do: its body is one function compiled for the baseline.)
pub(crate) trait VectorKernel {
    /// What the kernel returns.
    type Output;
    /// The loops.
    fn run(self) -> Self::Output;
}

struct Dispatch<K>(K);

impl<K: VectorKernel> pulp::WithSimd for Dispatch<K> {
    type Output = K::Output;

    #[inline(always)]
    fn with_simd<S: pulp::Simd>(self, _simd: S) -> K::Output {
        self.0.run()
    }
}

/// Runs `kernel` on the best instruction set found at run time. Results do not depend on it: IEEE
/// add, mul, div and sqrt round identically in every lane, and Rust never contracts a * b + c
/// into an FMA, so the fused update stays bit-reproducible across CPUs.
pub(crate) fn vectorized<K: VectorKernel>(kernel: K) -> K::Output {
    pulp::Arch::new().dispatch(Dispatch(kernel))
}

/// Runs the matrix products on one thread or on `threads` rayon workers (gemm's own splitting).
#[derive(Clone, Copy, Debug)]
pub(crate) struct Gemm {
    parallelism: Parallelism,
}

impl Gemm {
    /// Products on `threads` threads (1 or fewer: the calling thread only).
    pub(crate) fn new(threads: usize) -> Self {
        let parallelism = if threads <= 1 { Parallelism::None } else { Parallelism::Rayon(threads) };
        Self { parallelism }
    }

    /// dst = lhs rhs, or dst += lhs rhs when `accumulate`.
    pub(crate) fn mul(&self, dst: &mut MatMut, lhs: Mat, rhs: Mat, accumulate: bool) {
        assert!(
            lhs.cols == rhs.rows && dst.rows == lhs.rows && dst.cols == rhs.cols,
            "matmul {}x{} = {}x{} * {}x{}",
            dst.rows,
            dst.cols,
            lhs.rows,
            lhs.cols,
            rhs.rows,
            rhs.cols
        );
        let (m, n, k) = (lhs.rows, rhs.cols, lhs.cols);
        if m == 0 || n == 0 {
            return;
        }
        if k == 0 {
            if !accumulate {
                for i in 0..m {
                    dst.row_mut(i).fill(0.0);
                }
            }
            return;
        }
        // dst = alpha * dst + beta * lhs rhs, reading dst only when accumulating.
        let alpha = if accumulate { 1.0 } else { 0.0 };
        // SAFETY: every view was bounds-checked at construction (`extent` <= len) and slicing keeps
        // that invariant, so gemm reads lhs/rhs and writes dst strictly inside their slices; the
        // shapes agree (checked above); `dst` is a unique `&mut` borrow, so it cannot alias the shared
        // `lhs`/`rhs` borrows; strides are the views' own, all non-negative and < isize::MAX
        // because the slices exist.
        unsafe {
            gemm::gemm(
                m,
                n,
                k,
                dst.data.as_mut_ptr(),
                1,
                dst.rs as isize,
                accumulate,
                lhs.data.as_ptr(),
                lhs.cs as isize,
                lhs.rs as isize,
                rhs.data.as_ptr(),
                rhs.cs as isize,
                rhs.rs as isize,
                alpha,
                1.0,
                false,
                false,
                false,
                self.parallelism,
            );
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn naive(a: &[f32], b: &[f32], m: usize, k: usize, n: usize) -> Vec<f32> {
        let mut c = vec![0.0; m * n];
        for i in 0..m {
            for j in 0..n {
                c[i * n + j] = (0..k).map(|p| a[i * k + p] * b[p * n + j]).sum();
            }
        }
        c
    }

    #[test]
    fn transposed_and_column_block_views_multiply_like_dense_matrices() {
        let (m, k, n) = (5, 3, 4);
        let a: Vec<f32> = (0..m * k).map(|i| (i as f32 * 0.37).sin()).collect();
        let b: Vec<f32> = (0..k * n).map(|i| (i as f32 * 0.11).cos()).collect();
        let want = naive(&a, &b, m, k, n);
        // b^T stored [n, k], used through .t(); dst is the middle block of a 5 x 8 buffer.
        let bt: Vec<f32> = (0..n * k).map(|i| b[(i % k) * n + i / k]).collect();
        let mut wide = vec![7.0; m * 8];
        let mut dst = MatMut::strided(&mut wide, m, 8, 8).columns(2, n);
        Gemm::new(1).mul(&mut dst, Mat::dense(&a, m, k), Mat::dense(&bt, n, k).t(), false);
        for i in 0..m {
            assert_eq!(wide[i * 8], 7.0);
            for j in 0..n {
                assert!((wide[i * 8 + 2 + j] - want[i * n + j]).abs() < 1e-6);
            }
        }
        // Accumulate a^T-based product: (a^T)^T b = a b again, added on top.
        let at: Vec<f32> = (0..k * m).map(|i| a[(i % m) * k + i / m]).collect();
        let mut dst = MatMut::strided(&mut wide, m, 8, 8).columns(2, n);
        Gemm::new(1).mul(&mut dst, Mat::dense(&at, k, m).t(), Mat::dense(&b, k, n), true);
        assert!((wide[8 + 3] - 2.0 * want[n + 1]).abs() < 1e-5);
    }

    #[test]
    #[should_panic(expected = "exceeds")]
    fn out_of_bounds_views_are_refused() {
        let data = [0.0f32; 5];
        let _ = Mat::strided(&data, 2, 3, 3);
    }
}
