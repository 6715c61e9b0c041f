//! Symmetric-tensor helpers over glam's `DMat2` and `DMat3`.

use glam::{DMat2, DMat3, DVec2, DVec3};
use std::ops::{Add, Mul, Sub};

pub trait Matrix:
    Copy
    + Send
    + Sync
    + std::fmt::Debug
    + PartialEq
    + Add<Output = Self>
    + Sub<Output = Self>
    + Mul<f64, Output = Self>
    + serde::Serialize
    + serde::de::DeserializeOwned
{
    const DIM: usize;
    fn identity() -> Self;
    fn det(&self) -> f64;
    fn inverse(&self) -> Self;
    fn trace(&self) -> f64;
    /// Frobenius norm.
    fn norm(&self) -> f64;
    /// Deviatoric part X − tr(X)/d I.
    #[inline]
    fn dev(&self) -> Self {
        *self - Self::identity() * (self.trace() / Self::DIM as f64)
    }
    /// Eigenvalues (first DIM entries used, the rest 0) and the orthogonal matrix Q whose
    /// columns are the eigenvectors of a symmetric matrix: self = Q diag(values) Qᵀ. Only the
    /// symmetric part of `self` is read; the eigenvalues are not sorted.
    fn sym_eigen(&self) -> ([f64; 3], Self);
    /// Q diag(values) Qᵀ, exactly symmetric.
    fn from_eigen(values: [f64; 3], q: &Self) -> Self;
    /// The leading DIM × DIM block of a 3 × 3 matrix given by rows.
    fn from_rows3(a: [[f64; 3]; 3]) -> Self;
}

impl Matrix for DMat2 {
    const DIM: usize = 2;
    #[inline]
    fn identity() -> Self {
        DMat2::IDENTITY
    }
    #[inline]
    fn det(&self) -> f64 {
        self.determinant()
    }
    #[inline]
    fn inverse(&self) -> Self {
        DMat2::inverse(self)
    }
    #[inline]
    fn trace(&self) -> f64 {
        self.x_axis.x + self.y_axis.y
    }
    #[inline]
    fn norm(&self) -> f64 {
        (self.x_axis.length_squared() + self.y_axis.length_squared()).sqrt()
    }
    /// Closed form: with m = (a+c)/2, h = (a−c)/2, r = √(h² + b²) the eigenvalues are m ± r and
    /// Q the rotation by θ with (cos 2θ, sin 2θ) = (h, b)/r. cos θ and sin θ come from the
    /// half-angle formulas without trig, taking the larger of the two from its square root
    /// (≥ 1/√2, no cancellation) and the other from sin 2θ.
    #[inline]
    fn sym_eigen(&self) -> ([f64; 3], Self) {
        let (a, c) = (self.x_axis.x, self.y_axis.y);
        let b = 0.5 * (self.x_axis.y + self.y_axis.x);
        let (m, h) = (0.5 * (a + c), 0.5 * (a - c));
        let r = (h * h + b * b).sqrt();
        // Diagonal to round-off (this includes equal eigenvalues, and an off-diagonal so small
        // that b² underflows, where h / r would be 0 / 0): exact.
        if b.abs() <= 1e-18 * a.abs().max(c.abs()) || r == 0.0 {
            return ([a, c, 0.0], DMat2::IDENTITY);
        }
        let (cos, sin) = if h >= 0.0 {
            let cos = (0.5 * (1.0 + h / r)).sqrt();
            (cos, b / (2.0 * r * cos))
        } else {
            let sin = (0.5 * (1.0 - h / r)).sqrt();
            (b / (2.0 * r * sin), sin)
        };
        ([m + r, m - r, 0.0], DMat2::from_cols(DVec2::new(cos, sin), DVec2::new(-sin, cos)))
    }
    #[inline]
    fn from_eigen(v: [f64; 3], q: &Self) -> Self {
        let (a, b) = (q.x_axis, q.y_axis);
        let xx = v[0] * a.x * a.x + v[1] * b.x * b.x;
        let xy = v[0] * a.x * a.y + v[1] * b.x * b.y;
        let yy = v[0] * a.y * a.y + v[1] * b.y * b.y;
        DMat2::from_cols(DVec2::new(xx, xy), DVec2::new(xy, yy))
    }
    #[inline]
    fn from_rows3(a: [[f64; 3]; 3]) -> Self {
        DMat2::from_cols(DVec2::new(a[0][0], a[1][0]), DVec2::new(a[0][1], a[1][1]))
    }
}

impl Matrix for DMat3 {
    const DIM: usize = 3;
    #[inline]
    fn identity() -> Self {
        DMat3::IDENTITY
    }
    #[inline]
    fn det(&self) -> f64 {
        self.determinant()
    }
    #[inline]
    fn inverse(&self) -> Self {
        DMat3::inverse(self)
    }
    #[inline]
    fn trace(&self) -> f64 {
        self.x_axis.x + self.y_axis.y + self.z_axis.z
    }
    #[inline]
    fn norm(&self) -> f64 {
        (self.x_axis.length_squared() + self.y_axis.length_squared() + self.z_axis.length_squared()).sqrt()
    }
    /// Cyclic Jacobi: rotations zeroing the off-diagonal entries (0,1), (0,2), (1,2) in turn,
    /// tangent from the stable root of t² + 2θt − 1 = 0 (no trig), until the off-diagonal part
    /// is below 1e-15 of the Frobenius norm. Convergence is quadratic: 3–5 sweeps in practice,
    /// at most 10. Robust for repeated eigenvalues (no eigenvector is formed from a null space).
    #[inline]
    fn sym_eigen(&self) -> ([f64; 3], Self) {
        let mut d = [self.x_axis.x, self.y_axis.y, self.z_axis.z];
        // o[r] is the entry coupling the two indices other than r.
        let mut o = [
            0.5 * (self.y_axis.z + self.z_axis.y),
            0.5 * (self.x_axis.z + self.z_axis.x),
            0.5 * (self.x_axis.y + self.y_axis.x),
        ];
        let mut v = [DVec3::X, DVec3::Y, DVec3::Z];
        for _sweep in 0..10 {
            let off = o[0] * o[0] + o[1] * o[1] + o[2] * o[2];
            let diag = d[0] * d[0] + d[1] * d[1] + d[2] * d[2];
            if off <= 1e-30 * (diag + 2.0 * off) {
                break;
            }
            for (p, q, r) in [(0, 1, 2), (0, 2, 1), (1, 2, 0)] {
                let apq = o[r];
                if apq == 0.0 {
                    continue;
                }
                let theta = (d[q] - d[p]) / (2.0 * apq);
                // t = tan of the rotation angle, the smaller root (|angle| ≤ π/4). For |θ| > 1e8
                // (the late sweeps) t = 1/(2θ) and c = 1 to machine precision: no sqrt, no overflow.
                let (t, c) = if theta.abs() > 1e8 {
                    (0.5 / theta, 1.0)
                } else {
                    let t = theta.signum() / (theta.abs() + (theta * theta + 1.0).sqrt());
                    (t, 1.0 / (t * t + 1.0).sqrt())
                };
                let s = t * c;
                d[p] -= t * apq;
                d[q] += t * apq;
                o[r] = 0.0;
                let (arp, arq) = (o[q], o[p]);
                o[q] = c * arp - s * arq;
                o[p] = s * arp + c * arq;
                let (vp, vq) = (v[p], v[q]);
                v[p] = vp * c - vq * s;
                v[q] = vp * s + vq * c;
            }
        }
        (d, DMat3::from_cols(v[0], v[1], v[2]))
    }
    #[inline]
    fn from_eigen(v: [f64; 3], q: &Self) -> Self {
        let (a, b, c) = (q.x_axis, q.y_axis, q.z_axis);
        let (wa, wb, wc) = (a * v[0], b * v[1], c * v[2]);
        let xx = wa.x * a.x + wb.x * b.x + wc.x * c.x;
        let xy = wa.x * a.y + wb.x * b.y + wc.x * c.y;
        let xz = wa.x * a.z + wb.x * b.z + wc.x * c.z;
        let yy = wa.y * a.y + wb.y * b.y + wc.y * c.y;
        let yz = wa.y * a.z + wb.y * b.z + wc.y * c.z;
        let zz = wa.z * a.z + wb.z * b.z + wc.z * c.z;
        DMat3::from_cols(DVec3::new(xx, xy, xz), DVec3::new(xy, yy, yz), DVec3::new(xz, yz, zz))
    }
    #[inline]
    fn from_rows3(a: [[f64; 3]; 3]) -> Self {
        DMat3::from_cols(
            DVec3::new(a[0][0], a[1][0], a[2][0]),
            DVec3::new(a[0][1], a[1][1], a[2][1]),
            DVec3::new(a[0][2], a[1][2], a[2][2]),
        )
    }
}

/// A dimension with its matrix type: what the MPM kernels need beyond vectors.
pub trait MpmSpace: grains_grid::Space {
    type M: Matrix;
    /// a ⊗ b (a bᵀ).
    fn outer(a: Self::V, b: Self::V) -> Self::M;
    fn mul_vec(m: &Self::M, v: Self::V) -> Self::V;
    fn mul(a: &Self::M, b: &Self::M) -> Self::M;
    fn transpose(m: &Self::M) -> Self::M;
}

impl MpmSpace for grains_grid::D2 {
    type M = DMat2;
    #[inline]
    fn outer(a: glam::DVec2, b: glam::DVec2) -> DMat2 {
        DMat2::from_cols(a * b.x, a * b.y)
    }
    #[inline]
    fn mul_vec(m: &DMat2, v: glam::DVec2) -> glam::DVec2 {
        *m * v
    }
    #[inline]
    fn mul(a: &DMat2, b: &DMat2) -> DMat2 {
        *a * *b
    }
    #[inline]
    fn transpose(m: &DMat2) -> DMat2 {
        m.transpose()
    }
}

impl MpmSpace for grains_grid::D3 {
    type M = DMat3;
    #[inline]
    fn outer(a: glam::DVec3, b: glam::DVec3) -> DMat3 {
        DMat3::from_cols(a * b.x, a * b.y, a * b.z)
    }
    #[inline]
    fn mul_vec(m: &DMat3, v: glam::DVec3) -> glam::DVec3 {
        *m * v
    }
    #[inline]
    fn mul(a: &DMat3, b: &DMat3) -> DMat3 {
        *a * *b
    }
    #[inline]
    fn transpose(m: &DMat3) -> DMat3 {
        m.transpose()
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use glam::DQuat;

    use grains_grid::rng::Rng;

    /// Checks self = Q diag Qᵀ to 1e-13 relative, QᵀQ = I, an exactly symmetric
    /// reconstruction, and (when given) the eigenvalues against the known ones.
    #[inline]
    fn check<M: Matrix>(a: &M, known: Option<[f64; 3]>, transpose_mul: impl Fn(&M, &M) -> M) {
        let (values, q) = a.sym_eigen();
        let r = M::from_eigen(values, &q);
        let scale = a.norm();
        assert!(
            (r - *a).norm() <= 1e-13 * scale,
            "reconstruction error {} for {a:?}",
            (r - *a).norm()
        );
        let qtq = transpose_mul(&q, &q);
        assert!(
            (qtq - M::identity()).norm() < 1e-14,
            "QᵀQ − I = {:?} for {a:?}",
            qtq - M::identity()
        );
        assert_eq!(r, transpose_mul(&r, &M::identity()), "from_eigen must be exactly symmetric");
        if let Some(known) = known {
            let d = M::DIM;
            let (mut got, mut want) = (values[..d].to_vec(), known[..d].to_vec());
            got.sort_by(f64::total_cmp);
            want.sort_by(f64::total_cmp);
            let largest = want.iter().fold(0.0f64, |m, x| m.max(x.abs()));
            for (g, w) in got.iter().zip(&want) {
                assert!((g - w).abs() <= 1e-13 * largest, "eigenvalues {got:?} vs {want:?} for {a:?}");
            }
        }
    }

    #[inline]
    fn t2(a: &DMat2, b: &DMat2) -> DMat2 {
        a.transpose() * *b
    }
    #[inline]
    fn t3(a: &DMat3, b: &DMat3) -> DMat3 {
        a.transpose() * *b
    }

    #[test]
    #[inline]
    fn sym_eigen_2d_reconstructs_with_orthogonal_eigenvectors() {
        let mut rng = Rng::new(0x9e37_79b9_7f4a_7c15);
        let sym = |a: f64, b: f64, c: f64| DMat2::from_cols(DVec2::new(a, b), DVec2::new(b, c));
        // Edge cases: zero, multiples of I, diagonal either way round, pure off-diagonal,
        // tiny off-diagonal on either sign of a − c, a huge eigenvalue ratio.
        for (a, b, c) in [
            (0.0, 0.0, 0.0),
            (2.5, 0.0, 2.5),
            (3.0, 0.0, -1.0),
            (-1.0, 0.0, 3.0),
            (0.0, 1.0, 0.0),
            (1.0, 1e-17, 1.0 + 1e-9),
            (1.0 + 1e-9, -1e-17, 1.0),
            (1e6, 1.0, 1e-6),
            // Equal diagonal and an off-diagonal whose square underflows (a stress-free
            // surface point of the 2D collapse benchmark: once 0 / 0 and NaN stresses).
            (1.0, 1.4e-193, 1.0),
            (1.0, 1e-170, 1.0),
            (0.0, 1e-170, 0.0),
        ] {
            check(&sym(a, b, c), None, t2);
        }
        for k in 0..500 {
            check(&sym(rng.signed(), rng.signed(), rng.signed()), None, t2);
            // Known eigenvalues: R diag Rᵀ, with repeated and nearly repeated pairs.
            let l0 = rng.signed() * 10.0;
            let l1 = match k % 3 {
                0 => l0,
                1 => l0 * (1.0 + 1e-10),
                _ => rng.signed() * 10.0,
            };
            let rot = DMat2::from_angle(rng.signed() * 4.0);
            let a = rot * DMat2::from_diagonal(DVec2::new(l0, l1)) * rot.transpose();
            check(&a, Some([l0, l1, 0.0]), t2);
        }
    }

    #[test]
    #[inline]
    fn sym_eigen_3d_reconstructs_with_orthogonal_eigenvectors() {
        let mut rng = Rng::new(0x2545_f491_4f6c_dd1d);
        let sym = |d: [f64; 3], o: [f64; 3]| {
            DMat3::from_cols(
                DVec3::new(d[0], o[2], o[1]),
                DVec3::new(o[2], d[1], o[0]),
                DVec3::new(o[1], o[0], d[2]),
            )
        };
        for (d, o) in [
            ([0.0; 3], [0.0; 3]),
            ([2.0; 3], [0.0; 3]),
            ([3.0, -1.0, 0.5], [0.0; 3]),
            ([0.0; 3], [1.0, 1.0, 1.0]),
            ([1.0, 1.0, 1.0 + 1e-9], [1e-17, 0.0, -1e-17]),
            ([1e6, 1.0, 1e-6], [1.0, 1e-3, 1.0]),
        ] {
            check(&sym(d, o), None, t3);
        }
        for k in 0..500 {
            let mut r = || rng.signed();
            check(&sym([r(), r(), r()], [r(), r(), r()]), None, t3);
            let l = [r() * 10.0, r() * 10.0, r() * 10.0];
            let l = match k % 4 {
                0 => [l[0], l[0], l[2]],
                1 => [l[0]; 3],
                2 => [l[0], l[0] * (1.0 + 1e-10), l[2]],
                _ => l,
            };
            let rot = DMat3::from_quat(DQuat::from_axis_angle(DVec3::new(r(), r(), r() + 2.0).normalize(), r() * 4.0));
            let a = rot * DMat3::from_diagonal(DVec3::from_array(l)) * rot.transpose();
            check(&a, Some(l), t3);
        }
    }
}
