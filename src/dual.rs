//! Forward-mode automatic differentiation: a number with its gradient over `N` inputs, and [`Real`],
//! the arithmetic a model written once needs to run on `f64` (the simulation) or on [`Dual`] (its
//! exact Jacobian in one evaluation, instead of `2 N + 1` for central differences).
//!
//! For `f64` every operation is the plain one, in the order the model writes it, so a model made
//! generic gives the same bits as before. (A maintained crate, `num-dual`, does the same; this file is
//! the handful of operations the surface-bank model uses, without another dependency on nalgebra's
//! version.)

use std::ops::{Add, AddAssign, Div, DivAssign, Mul, MulAssign, Neg, Sub, SubAssign};

use nalgebra::{ClosedAddAssign, ClosedDivAssign, ClosedMulAssign, ClosedSubAssign, SMatrix, SVector, Scalar};
use num_traits::{One, Zero};

/// What a model generic over its number type may do with it, in nalgebra's vectors and matrices too.
pub trait Real:
    Copy
    + Scalar
    + Zero
    + One
    + ClosedAddAssign
    + ClosedSubAssign
    + ClosedMulAssign
    + ClosedDivAssign
    + Add<Output = Self>
    + Sub<Output = Self>
    + Mul<Output = Self>
    + Div<Output = Self>
    + Neg<Output = Self>
    + Add<f64, Output = Self>
    + Sub<f64, Output = Self>
    + Mul<f64, Output = Self>
    + Div<f64, Output = Self>
{
    /// A constant (no gradient).
    fn cst(v: f64) -> Self;
    /// The value.
    fn re(self) -> f64;
    fn sin_cos(self) -> (Self, Self);
    fn exp(self) -> Self;
    fn sqrt(self) -> Self;
}

impl Real for f64 {
    #[inline(always)]
    fn cst(v: f64) -> Self {
        v
    }
    #[inline(always)]
    fn re(self) -> f64 {
        self
    }
    #[inline(always)]
    fn sin_cos(self) -> (f64, f64) {
        f64::sin_cos(self)
    }
    #[inline(always)]
    fn exp(self) -> f64 {
        f64::exp(self)
    }
    #[inline(always)]
    fn sqrt(self) -> f64 {
        f64::sqrt(self)
    }
}

/// A value and its derivatives with respect to `N` inputs.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Dual<const N: usize> {
    pub v: f64,
    pub d: [f64; N],
}

impl<const N: usize> Dual<N> {
    /// Input `i` at value `v` (its derivative with respect to itself 1).
    #[inline(always)]
    pub fn input(v: f64, i: usize) -> Self {
        let mut d = [0.0; N];
        d[i] = 1.0;
        Dual { v, d }
    }

    /// `g(v)` with `g'(v) = slope`: the chain rule.
    #[inline(always)]
    fn chain(self, v: f64, slope: f64) -> Self {
        Dual { v, d: self.d.map(|x| x * slope) }
    }
}

/// `g(x)` and its Jacobian `dg/dx`, exact, from one evaluation of `g` on dual numbers (the values are
/// the `f64` evaluation's to the bit).
pub fn value_and_jacobian<const N: usize, const R: usize>(
    x: &SVector<f64, N>,
    g: impl Fn(&SVector<Dual<N>, N>) -> SVector<Dual<N>, R>,
) -> (SVector<f64, R>, SMatrix<f64, R, N>) {
    let gx = g(&SVector::from_fn(|i, _| Dual::input(x[i], i)));
    (gx.map(|e| e.v), SMatrix::from_fn(|r, c| gx[r].d[c]))
}

impl<const N: usize> Real for Dual<N> {
    #[inline(always)]
    fn cst(v: f64) -> Self {
        Dual { v, d: [0.0; N] }
    }
    #[inline(always)]
    fn re(self) -> f64 {
        self.v
    }
    #[inline(always)]
    fn sin_cos(self) -> (Self, Self) {
        let (s, c) = self.v.sin_cos();
        (self.chain(s, c), self.chain(c, -s))
    }
    #[inline(always)]
    fn exp(self) -> Self {
        let e = self.v.exp();
        self.chain(e, e)
    }
    /// At 0, where the square root has no derivative, the slope is taken as 0: the models use it for a
    /// norm `|v|` that multiplies `v` (drag), and `|v| v` has the derivative 0 there, which 0 gives and
    /// `0 * inf` would turn into NaN.
    #[inline(always)]
    fn sqrt(self) -> Self {
        let r = self.v.sqrt();
        self.chain(r, if r > 0.0 { 0.5 / r } else { 0.0 })
    }
}

impl<const N: usize> Add for Dual<N> {
    type Output = Self;
    #[inline(always)]
    fn add(self, o: Self) -> Self {
        Dual { v: self.v + o.v, d: std::array::from_fn(|i| self.d[i] + o.d[i]) }
    }
}

impl<const N: usize> Sub for Dual<N> {
    type Output = Self;
    #[inline(always)]
    fn sub(self, o: Self) -> Self {
        Dual { v: self.v - o.v, d: std::array::from_fn(|i| self.d[i] - o.d[i]) }
    }
}

impl<const N: usize> Mul for Dual<N> {
    type Output = Self;
    #[inline(always)]
    fn mul(self, o: Self) -> Self {
        Dual { v: self.v * o.v, d: std::array::from_fn(|i| self.d[i] * o.v + self.v * o.d[i]) }
    }
}

impl<const N: usize> Div for Dual<N> {
    type Output = Self;
    #[inline(always)]
    fn div(self, o: Self) -> Self {
        let inv = 1.0 / o.v;
        let v = self.v / o.v;
        Dual { v, d: std::array::from_fn(|i| (self.d[i] - v * o.d[i]) * inv) }
    }
}

impl<const N: usize> Neg for Dual<N> {
    type Output = Self;
    #[inline(always)]
    fn neg(self) -> Self {
        Dual { v: -self.v, d: self.d.map(|x| -x) }
    }
}

impl<const N: usize> Zero for Dual<N> {
    #[inline(always)]
    fn zero() -> Self {
        Dual::cst(0.0)
    }
    #[inline(always)]
    fn is_zero(&self) -> bool {
        self.v == 0.0 && self.d.iter().all(|d| *d == 0.0)
    }
}

impl<const N: usize> One for Dual<N> {
    #[inline(always)]
    fn one() -> Self {
        Dual::cst(1.0)
    }
}

/// `a op= b` as `a = a op b`, for each of the four operators.
macro_rules! assign_ops {
    ($($trait:ident $method:ident $op:tt),*) => {$(
        impl<const N: usize> $trait for Dual<N> {
            #[inline(always)]
            fn $method(&mut self, o: Self) {
                *self = *self $op o;
            }
        }
    )*};
}

assign_ops!(AddAssign add_assign +, SubAssign sub_assign -, MulAssign mul_assign *, DivAssign div_assign /);

impl<const N: usize> Add<f64> for Dual<N> {
    type Output = Self;
    #[inline(always)]
    fn add(self, o: f64) -> Self {
        Dual { v: self.v + o, d: self.d }
    }
}

impl<const N: usize> Sub<f64> for Dual<N> {
    type Output = Self;
    #[inline(always)]
    fn sub(self, o: f64) -> Self {
        Dual { v: self.v - o, d: self.d }
    }
}

impl<const N: usize> Mul<f64> for Dual<N> {
    type Output = Self;
    #[inline(always)]
    fn mul(self, o: f64) -> Self {
        Dual { v: self.v * o, d: self.d.map(|x| x * o) }
    }
}

impl<const N: usize> Div<f64> for Dual<N> {
    type Output = Self;
    #[inline(always)]
    fn div(self, o: f64) -> Self {
        Dual { v: self.v / o, d: self.d.map(|x| x / o) }
    }
}

impl<const N: usize> Add<Dual<N>> for f64 {
    type Output = Dual<N>;
    #[inline(always)]
    fn add(self, o: Dual<N>) -> Dual<N> {
        Dual { v: self + o.v, d: o.d }
    }
}

impl<const N: usize> Sub<Dual<N>> for f64 {
    type Output = Dual<N>;
    #[inline(always)]
    fn sub(self, o: Dual<N>) -> Dual<N> {
        Dual { v: self - o.v, d: o.d.map(|x| -x) }
    }
}

impl<const N: usize> Mul<Dual<N>> for f64 {
    type Output = Dual<N>;
    #[inline(always)]
    fn mul(self, o: Dual<N>) -> Dual<N> {
        Dual { v: self * o.v, d: o.d.map(|x| self * x) }
    }
}

impl<const N: usize> Div<Dual<N>> for f64 {
    type Output = Dual<N>;
    #[inline(always)]
    fn div(self, o: Dual<N>) -> Dual<N> {
        let v = self / o.v;
        Dual { v, d: o.d.map(|x| -v * x / o.v) }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// `f(x, y) = exp(x) sin(y) / sqrt(x y) + 3 x - 2 / y` against its hand derivatives at a point.
    #[test]
    fn derivatives_are_the_analytic_ones() {
        fn f<T: Real>(x: T, y: T) -> T
        where
            f64: Sub<T, Output = T> + Div<T, Output = T> + Mul<T, Output = T>,
        {
            let (s, _) = y.sin_cos();
            x.exp() * s / (x * y).sqrt() + 3.0 * x - 2.0 / y
        }
        let (x, y) = (0.7, 1.3);
        let r = f(Dual::<2>::input(x, 0), Dual::<2>::input(y, 1));
        let g = (x * y).sqrt();
        let dx = x.exp() * y.sin() * (1.0 / g - 0.5 * y / (g * g * g)) + 3.0;
        let dy = x.exp() * (y.cos() / g - y.sin() * 0.5 * x / (g * g * g)) + 2.0 / (y * y);
        assert_eq!(r.v, f(x, y), "the value is the f64 evaluation's, to the bit");
        assert!((r.d[0] - dx).abs() < 1e-14 && (r.d[1] - dy).abs() < 1e-14, "{r:?} vs {dx} {dy}");
    }
}
