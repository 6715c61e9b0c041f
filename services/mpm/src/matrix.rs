//! Symmetric-tensor helpers over glam's `DMat2` and `DMat3`.

use glam::{DMat2, DMat3};
use std::ops::{Add, Mul, Sub};

pub trait Matrix: Copy + std::fmt::Debug + PartialEq + Add<Output = Self> + Sub<Output = Self> + Mul<f64, Output = Self> {
    const DIM: usize;
    fn identity() -> Self;
    fn det(&self) -> f64;
    fn inverse(&self) -> Self;
    fn trace(&self) -> f64;
    /// Frobenius norm.
    fn norm(&self) -> f64;
    /// Deviatoric part X − tr(X)/d I.
    fn dev(&self) -> Self {
        *self - Self::identity() * (self.trace() / Self::DIM as f64)
    }
}

impl Matrix for DMat2 {
    const DIM: usize = 2;
    fn identity() -> Self {
        DMat2::IDENTITY
    }
    fn det(&self) -> f64 {
        self.determinant()
    }
    fn inverse(&self) -> Self {
        DMat2::inverse(self)
    }
    fn trace(&self) -> f64 {
        self.x_axis.x + self.y_axis.y
    }
    fn norm(&self) -> f64 {
        (self.x_axis.length_squared() + self.y_axis.length_squared()).sqrt()
    }
}

impl Matrix for DMat3 {
    const DIM: usize = 3;
    fn identity() -> Self {
        DMat3::IDENTITY
    }
    fn det(&self) -> f64 {
        self.determinant()
    }
    fn inverse(&self) -> Self {
        DMat3::inverse(self)
    }
    fn trace(&self) -> f64 {
        self.x_axis.x + self.y_axis.y + self.z_axis.z
    }
    fn norm(&self) -> f64 {
        (self.x_axis.length_squared() + self.y_axis.length_squared() + self.z_axis.length_squared()).sqrt()
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
    fn outer(a: glam::DVec2, b: glam::DVec2) -> DMat2 {
        DMat2::from_cols(a * b.x, a * b.y)
    }
    fn mul_vec(m: &DMat2, v: glam::DVec2) -> glam::DVec2 {
        *m * v
    }
    fn mul(a: &DMat2, b: &DMat2) -> DMat2 {
        *a * *b
    }
    fn transpose(m: &DMat2) -> DMat2 {
        m.transpose()
    }
}

impl MpmSpace for grains_grid::D3 {
    type M = DMat3;
    fn outer(a: glam::DVec3, b: glam::DVec3) -> DMat3 {
        DMat3::from_cols(a * b.x, a * b.y, a * b.z)
    }
    fn mul_vec(m: &DMat3, v: glam::DVec3) -> glam::DVec3 {
        *m * v
    }
    fn mul(a: &DMat3, b: &DMat3) -> DMat3 {
        *a * *b
    }
    fn transpose(m: &DMat3) -> DMat3 {
        m.transpose()
    }
}
