//! Reductions that round exactly as numpy's do, so rewards match the Python references bit for bit.

/// `np.sum` of a contiguous float64 array: numpy's pairwise summation (8 partial sums per block of up
/// to 128 elements, combined as ((r0+r1)+(r2+r3))+((r4+r5)+(r6+r7)), blocks split in halves).
pub(crate) fn sum(values: &[f64]) -> f64 {
    const BLOCK: usize = 128;
    let n = values.len();
    if n < 8 {
        values.iter().fold(0.0, |acc, v| acc + v)
    } else if n <= BLOCK {
        let mut r = [0.0f64; 8];
        r.copy_from_slice(&values[..8]);
        let unrolled = n - n % 8;
        for chunk in values[8..unrolled].chunks_exact(8) {
            for (acc, v) in r.iter_mut().zip(chunk) {
                *acc += v;
            }
        }
        let mut res = ((r[0] + r[1]) + (r[2] + r[3])) + ((r[4] + r[5]) + (r[6] + r[7]));
        for v in &values[unrolled..] {
            res += v;
        }
        res
    } else {
        let half = (n / 2) - (n / 2) % 8;
        sum(&values[..half]) + sum(&values[half..])
    }
}

/// `np.sum(np.square(values))`.
pub(crate) fn sum_of_squares(values: impl Iterator<Item = f64>) -> f64 {
    let squares: Vec<f64> = values.map(|v| v * v).collect();
    sum(&squares)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn pairwise_order_differs_from_a_left_fold_where_numpy_does() {
        // 1e16 + 1 + ... : a left fold loses the ones that numpy's pairwise tree keeps together.
        let mut v = vec![1.0; 16];
        v[0] = 1e16;
        let fold = v.iter().fold(0.0, |a, b| a + b);
        assert_eq!(sum(&v), 1e16 + 14.0);
        assert_ne!(sum(&v), fold);
        assert_eq!(sum(&[1.0, 2.0, 3.0]), 6.0);
        assert_eq!(sum(&vec![0.5; 300]), 150.0);
    }
}
