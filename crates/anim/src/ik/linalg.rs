//! The chain solver's small dense systems, in `f64` on caller-owned
//! slices (row-major `n × n`), so a solve allocates nothing.

/// Solves `A·x = b` for symmetric positive-definite `A` by Cholesky,
/// overwriting `a` with its factor and `b` with `x`. `false` if a pivot is
/// not positive (then `a` and `b` hold garbage).
pub(crate) fn cholesky_solve(a: &mut [f64], b: &mut [f64], n: usize) -> bool {
    debug_assert!(a.len() >= n * n && b.len() >= n);
    for j in 0..n {
        let mut pivot = a[j * n + j];
        for k in 0..j {
            pivot -= a[j * n + k] * a[j * n + k];
        }
        if pivot.is_nan() || pivot <= 0.0 {
            return false;
        }
        let root = pivot.sqrt();
        a[j * n + j] = root;
        for i in j + 1..n {
            let mut v = a[i * n + j];
            for k in 0..j {
                v -= a[i * n + k] * a[j * n + k];
            }
            a[i * n + j] = v / root;
        }
    }
    // L·y = b, then Lᵀ·x = y.
    for i in 0..n {
        let mut v = b[i];
        for k in 0..i {
            v -= a[i * n + k] * b[k];
        }
        b[i] = v / a[i * n + i];
    }
    for i in (0..n).rev() {
        let mut v = b[i];
        for k in i + 1..n {
            v -= a[k * n + i] * b[k];
        }
        b[i] = v / a[i * n + i];
    }
    true
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn solves_a_hand_made_system() {
        // A = [[4, 2], [2, 3]], x = [1, -2] → b = [0, -4].
        let (mut a, mut b) = ([4.0, 2.0, 2.0, 3.0], [0.0, -4.0]);
        assert!(cholesky_solve(&mut a, &mut b, 2));
        assert!((b[0] - 1.0).abs() < 1e-14 && (b[1] + 2.0).abs() < 1e-14, "{b:?}");
    }

    #[test]
    fn refuses_an_indefinite_matrix() {
        let (mut a, mut b) = ([1.0, 2.0, 2.0, 1.0], [1.0, 1.0]);
        assert!(!cholesky_solve(&mut a, &mut b, 2));
    }
}
