//! Dense LU factorisation with partial pivoting, over real or complex entries: the linear
//! solves of the implicit integrator (`sim::radau`: the real and the complex Newton systems
//! of Radau IIA, and the sensitivity stage system). Matrices are row-major `n x n`.

use std::ops::{Add, Div, Mul, Neg, Sub};

/// The entries an [`Lu`] works on: `f64` and [`Complex`].
pub trait Entry:
    Copy
    + Add<Output = Self>
    + Sub<Output = Self>
    + Mul<Output = Self>
    + Div<Output = Self>
    + Neg<Output = Self>
{
    /// Zero.
    #[cfg(test)]
    const ZERO: Self;
    /// A magnitude for pivoting (`|re| + |im|` for a complex number).
    fn magnitude(self) -> f64;
}

impl Entry for f64 {
    #[cfg(test)]
    const ZERO: f64 = 0.0;
    fn magnitude(self) -> f64 {
        self.abs()
    }
}

/// A complex number, as much of one as the complex Newton system of Radau IIA needs.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct Complex {
    /// Real part.
    pub re: f64,
    /// Imaginary part.
    pub im: f64,
}

impl Complex {
    /// `re + i im`.
    pub const fn new(re: f64, im: f64) -> Self {
        Complex { re, im }
    }
}

impl Add for Complex {
    type Output = Complex;
    fn add(self, b: Complex) -> Complex {
        Complex::new(self.re + b.re, self.im + b.im)
    }
}

impl Sub for Complex {
    type Output = Complex;
    fn sub(self, b: Complex) -> Complex {
        Complex::new(self.re - b.re, self.im - b.im)
    }
}

impl Mul for Complex {
    type Output = Complex;
    fn mul(self, b: Complex) -> Complex {
        Complex::new(
            self.re * b.re - self.im * b.im,
            self.re * b.im + self.im * b.re,
        )
    }
}

impl Div for Complex {
    type Output = Complex;
    /// Smith's division, which neither overflows nor underflows needlessly.
    fn div(self, b: Complex) -> Complex {
        if b.re.abs() >= b.im.abs() {
            let ratio = b.im / b.re;
            let denominator = b.re + b.im * ratio;
            Complex::new(
                (self.re + self.im * ratio) / denominator,
                (self.im - self.re * ratio) / denominator,
            )
        } else {
            let ratio = b.re / b.im;
            let denominator = b.re * ratio + b.im;
            Complex::new(
                (self.re * ratio + self.im) / denominator,
                (self.im * ratio - self.re) / denominator,
            )
        }
    }
}

impl Neg for Complex {
    type Output = Complex;
    fn neg(self) -> Complex {
        Complex::new(-self.re, -self.im)
    }
}

impl Entry for Complex {
    #[cfg(test)]
    const ZERO: Complex = Complex::new(0.0, 0.0);
    fn magnitude(self) -> f64 {
        self.re.abs() + self.im.abs()
    }
}

/// The factors `P A = L U` of a square matrix (unit lower `L` and `U` stored together).
#[derive(Debug, Clone, PartialEq)]
pub struct Lu<T> {
    n: usize,
    factors: Vec<T>,
    pivots: Vec<usize>,
}

impl<T: Entry> Lu<T> {
    /// Factors `a` (`n x n`, row-major, consumed); `None` when `a` does not have `n * n`
    /// entries, or a pivot is zero or not finite (the matrix is singular to working
    /// precision, or holds a NaN).
    pub fn factor(mut a: Vec<T>, n: usize) -> Option<Lu<T>> {
        if a.len() != n * n {
            return None;
        }
        let mut pivots = Vec::with_capacity(n);
        for k in 0..n {
            let pivot = (k..n).max_by(|&i, &j| {
                a[i * n + k]
                    .magnitude()
                    .total_cmp(&a[j * n + k].magnitude())
            })?;
            let size = a[pivot * n + k].magnitude();
            if !(size > 0.0 && size.is_finite()) {
                return None;
            }
            if pivot != k {
                for j in 0..n {
                    a.swap(k * n + j, pivot * n + j);
                }
            }
            pivots.push(pivot);
            let diagonal = a[k * n + k];
            for i in k + 1..n {
                let factor = a[i * n + k] / diagonal;
                a[i * n + k] = factor;
                for j in k + 1..n {
                    a[i * n + j] = a[i * n + j] - factor * a[k * n + j];
                }
            }
        }
        Some(Lu {
            n,
            factors: a,
            pivots,
        })
    }

    /// Overwrites `b` (`n` entries) with the solution `x` of `a x = b`.
    pub fn solve_in_place(&self, b: &mut [T]) {
        let (n, lu) = (self.n, &self.factors);
        for (k, &pivot) in self.pivots.iter().enumerate() {
            b.swap(k, pivot);
        }
        for i in 0..n {
            let mut sum = b[i];
            for j in 0..i {
                sum = sum - lu[i * n + j] * b[j];
            }
            b[i] = sum;
        }
        for i in (0..n).rev() {
            let mut sum = b[i];
            for j in i + 1..n {
                sum = sum - lu[i * n + j] * b[j];
            }
            b[i] = sum / lu[i * n + i];
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// `a x` for a row-major `n x n` matrix.
    fn multiply<T: Entry>(a: &[T], x: &[T], n: usize) -> Vec<T> {
        (0..n)
            .map(|i| (0..n).fold(T::ZERO, |sum, j| sum + a[i * n + j] * x[j]))
            .collect()
    }

    #[test]
    fn real_solve_reproduces_the_right_hand_side() {
        // A matrix that needs pivoting: its first pivot is zero.
        let a = vec![0.0, 2.0, 1.0, 1.0, 1.0, 0.0, 3.0, -1.0, 4.0];
        let x = vec![1.5, -2.0, 0.25];
        let mut b = multiply(&a, &x, 3);
        Lu::factor(a, 3).unwrap().solve_in_place(&mut b);
        for (got, want) in b.iter().zip(&x) {
            assert!((got - want).abs() < 1e-14, "{got} vs {want}");
        }
    }

    #[test]
    fn complex_solve_reproduces_the_right_hand_side() {
        let c = Complex::new;
        let a = vec![c(1.0, 2.0), c(0.5, -1.0), c(-3.0, 0.25), c(2.0, 0.0)];
        let x = vec![c(0.3, -0.7), c(-1.1, 2.2)];
        let mut b = multiply(&a, &x, 2);
        Lu::factor(a, 2).unwrap().solve_in_place(&mut b);
        for (got, want) in b.iter().zip(&x) {
            assert!((*got - *want).magnitude() < 1e-14, "{got:?} vs {want:?}");
        }
    }

    #[test]
    fn complex_division_inverts_multiplication() {
        let (a, b) = (Complex::new(3.0, -4.0), Complex::new(1e-3, 2e5));
        let back = (a * b) / b;
        assert!((back - a).magnitude() < 1e-12);
        let back = (a * a) / a;
        assert!((back - a).magnitude() < 1e-12);
    }

    #[test]
    fn singular_and_malformed_matrices_are_refused() {
        assert!(Lu::factor(vec![1.0, 2.0, 2.0, 4.0], 2).is_none());
        assert!(Lu::factor(vec![1.0, f64::NAN, 0.0, 1.0], 2).is_none());
        assert!(Lu::factor(vec![1.0, 2.0, 3.0], 2).is_none());
    }
}
