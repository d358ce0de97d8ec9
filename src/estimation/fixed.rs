//! The two decompositions the filters run at every step, written for fixed sizes: the inverse of the
//! innovation covariance by LU with partial pivoting, and the positive-definiteness test of a covariance
//! by Cholesky. Each performs nalgebra's operations (`LU::new` + `try_inverse`, `Cholesky::new`) in
//! nalgebra's order, so the numbers are nalgebra's to the bit (tested on random, pivoting, singular and
//! indefinite matrices), without the general-matrix code's views, bounds and strides, which took most of
//! their time in the profiles of methods 004 and 001. Where nalgebra repeats one operation over
//! independent columns (the inverse's solves) it is done here across them, so the compiler can run
//! them in SIMD lanes: each entry still sees the same operations in the same order.
#![allow(non_snake_case)]

use nalgebra::SMatrix;

/// `A^-1` by LU with partial pivoting, as `A.lu().try_inverse()` (`None` when a pivot is zero), and the
/// determinant from the same factors, as `A.lu().determinant()` (which is `A.determinant()` from 4x4 on).
pub fn lu_inverse<const M: usize>(A: &SMatrix<f64, M, M>) -> (Option<SMatrix<f64, M, M>>, f64) {
    // Column-major like nalgebra: a[c][r] is row r of column c.
    let mut a: [[f64; M]; M] = std::array::from_fn(|c| std::array::from_fn(|r| A[(r, c)]));
    let mut swaps = [(0usize, 0usize); M];
    let mut swap_count = 0;
    for i in 0..M {
        // The first entry of largest magnitude at or below the diagonal (nalgebra's `icamax`).
        let (mut piv, mut largest) = (i, a[i][i].abs());
        for r in i + 1..M {
            if a[i][r].abs() > largest {
                (piv, largest) = (r, a[i][r].abs());
            }
        }
        let diag = a[i][piv];
        if diag == 0.0 {
            continue;
        }
        if piv != i {
            swaps[swap_count] = (i, piv);
            swap_count += 1;
            for column in a.iter_mut().take(i + 1) {
                column.swap(i, piv);
            }
        }
        let inv_diag = 1.0 / diag;
        for r in i + 1..M {
            a[i][r] *= inv_diag;
        }
        for c in i + 1..M {
            a[c].swap(i, piv);
            let pivot = a[c][i];
            for r in i + 1..M {
                a[c][r] = -pivot * a[i][r] + a[c][r];
            }
        }
    }
    // nalgebra's order: 1 times each pivot in turn, then the permutation's sign.
    let mut determinant = 1.0;
    for (i, column) in a.iter().enumerate() {
        determinant *= column[i];
    }
    let determinant = if swap_count % 2 == 0 { determinant } else { -determinant };
    // Solve L U X = P I. nalgebra solves column by column; the columns are independent and each
    // sees the same operations in the same order, so they are solved here side by side: x[r] is row r
    // of X across all its columns, and each step below is one operation on every column at once.
    let mut x: [[f64; M]; M] = std::array::from_fn(|r| std::array::from_fn(|c| f64::from(r == c)));
    for &(i1, i2) in &swaps[..swap_count] {
        x.swap(i1, i2);
    }
    for i in 0..M.saturating_sub(1) {
        let coeffs = x[i];
        for j in i + 1..M {
            let l = a[i][j];
            for (y, c) in x[j].iter_mut().zip(&coeffs) {
                *y = -c * l + *y;
            }
        }
    }
    for i in (0..M).rev() {
        let diag = a[i][i];
        if diag == 0.0 {
            return (None, determinant);
        }
        for y in x[i].iter_mut() {
            *y /= diag;
        }
        let coeffs = x[i];
        for j in 0..i {
            let u = a[i][j];
            for (y, c) in x[j].iter_mut().zip(&coeffs) {
                *y = -c * u + *y;
            }
        }
    }
    (Some(SMatrix::from_fn(|r, c| x[r][c])), determinant)
}

/// Whether `A` (its lower triangle) has a Cholesky factor, as `A.cholesky().is_some()`: every pivot
/// positive.
pub fn has_cholesky<const N: usize>(A: &SMatrix<f64, N, N>) -> bool {
    let mut a: [[f64; N]; N] = std::array::from_fn(|c| std::array::from_fn(|r| A[(r, c)]));
    for j in 0..N {
        for k in 0..j {
            let factor = -a[k][j];
            for r in j..N {
                a[j][r] = factor * a[k][r] + a[j][r];
            }
        }
        let diag = a[j][j];
        // nalgebra: zero, negative or NaN has no square root.
        if diag == 0.0 || diag.is_nan() || diag < 0.0 {
            return false;
        }
        let denom = diag.sqrt();
        a[j][j] = denom;
        for r in j + 1..N {
            a[j][r] /= denom;
        }
    }
    true
}

#[cfg(test)]
mod tests {
    use super::*;
    use nalgebra::{Const, DimMin};
    use rand::rngs::ChaCha8Rng;
    use rand::{RngExt, SeedableRng};

    fn random<const N: usize>(rng: &mut ChaCha8Rng) -> SMatrix<f64, N, N> {
        SMatrix::from_fn(|_, _| rng.random_range(-3.0..3.0))
    }

    /// Bit for bit nalgebra's, inverse and determinant, on matrices that pivot at every step, that need
    /// no pivoting, with exact zeros, singular ones, and covariances (symmetric positive definite) of 5,
    /// 6 and 12 states.
    #[test]
    fn lu_inverse_is_nalgebras_to_the_bit() {
        fn check<const N: usize>(A: SMatrix<f64, N, N>) -> bool
        where
            Const<N>: DimMin<Const<N>, Output = Const<N>>,
        {
            let (ours, determinant) = lu_inverse(&A);
            let theirs = A.lu().try_inverse();
            assert_eq!(ours.map(|m| m.map(f64::to_bits)), theirs.map(|m| m.map(f64::to_bits)), "{A}");
            assert_eq!(determinant.to_bits(), A.lu().determinant().to_bits(), "{A}");
            if N > 3 {
                assert_eq!(determinant.to_bits(), A.determinant().to_bits(), "{A}");
            }
            ours.is_some()
        }
        let mut rng = ChaCha8Rng::seed_from_u64(24);
        let mut inverted = 0;
        for _ in 0..500 {
            let A5 = random::<5>(&mut rng);
            inverted += check(A5) as usize;
            inverted += check(A5 * A5.transpose() + SMatrix::<f64, 5, 5>::identity() * 0.1) as usize;
            let A6 = random::<6>(&mut rng);
            inverted += check(A6) as usize;
            let A12 = random::<12>(&mut rng);
            inverted += check(A12 * A12.transpose()) as usize;
            // Diagonally dominant: no row exchanges at all.
            inverted += check(A6 + SMatrix::<f64, 6, 6>::identity() * 40.0) as usize;
        }
        assert_eq!(inverted, 2500);
        // Exact zeros and singular matrices: a zero column, a column that elimination zeroes exactly.
        let mut Z = random::<5>(&mut rng);
        Z.set_column(2, &nalgebra::Vector5::zeros());
        assert!(!check(Z));
        let mut Z = SMatrix::<f64, 3, 3>::new(1.0, 2.0, 3.0, 2.0, 4.0, 1.0, 4.0, 8.0, 5.0);
        assert!(!check(Z));
        Z[(2, 1)] = 8.5;
        assert!(check(Z));
        assert!(!check(SMatrix::<f64, 4, 4>::zeros()));
        let mut P = SMatrix::<f64, 4, 4>::zeros();
        (P[(1, 0)], P[(0, 1)], P[(3, 2)], P[(2, 3)]) = (2.0, -1.0, 0.5, 4.0);
        assert!(check(P));
    }

    #[test]
    fn has_cholesky_decides_as_nalgebra() {
        let mut rng = ChaCha8Rng::seed_from_u64(25);
        let (mut yes, mut no) = (0, 0);
        for _ in 0..2000 {
            let A = random::<6>(&mut rng);
            // Around the boundary: a Gram matrix shifted by a random multiple of I, some definite, some not.
            let shift = rng.random_range(-2.0..0.5);
            let S = A * A.transpose() * 0.05 + SMatrix::<f64, 6, 6>::identity() * shift;
            let expected = S.cholesky().is_some();
            assert_eq!(has_cholesky(&S), expected, "{S}");
            if expected { yes += 1 } else { no += 1 }
        }
        assert!(yes > 200 && no > 200, "{yes} definite, {no} not");
        assert!(!has_cholesky(&SMatrix::<f64, 3, 3>::zeros()));
        assert!(!has_cholesky(&SMatrix::<f64, 2, 2>::from_element(f64::NAN)));
        // The positive semi-definite boundary: a zero pivot.
        assert!(!has_cholesky(&SMatrix::<f64, 2, 2>::new(1.0, 1.0, 1.0, 1.0)));
    }
}
