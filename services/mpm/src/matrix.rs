//! Symmetric-tensor helpers over glam's `DMat2` and `DMat3`.

use glam::{DMat2, DMat3};
use std::ops::{Add, Mul, Sub};

pub trait Matrix: Copy + std::fmt::Debug + PartialEq + Add<Output = Self> + Sub<Output = Self> + Mul<f64, Output = Self> {
    const DIM: usize;
    fn identity() -> Self;
    fn det(&self) -> f64;
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
    fn trace(&self) -> f64 {
        self.x_axis.x + self.y_axis.y + self.z_axis.z
    }
    fn norm(&self) -> f64 {
        (self.x_axis.length_squared() + self.y_axis.length_squared() + self.z_axis.length_squared()).sqrt()
    }
}
