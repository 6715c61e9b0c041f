//! The dimension as a type: 2D disks (3 degrees of freedom) and 3D spheres (6), sharing every
//! kernel. Vectors are glam `DVec2`/`DVec3`; angular quantities are a scalar (the z component)
//! in 2D and a `DVec3` in 3D; orientation is an angle in 2D and a unit quaternion in 3D.

use glam::{DQuat, DVec2, DVec3};
use std::fmt::Debug;
use std::ops::{Add, AddAssign, Mul, Neg, Sub, SubAssign};

/// The bounds and periods of a box for [`Vector::wrap`]: [min, max) on the `periodic` axes;
/// ±∞ and a period of 0 on the others, which never wrap.
pub fn wrap_box<S: Space>(min: [f64; 3], max: [f64; 3], periodic: [bool; 3]) -> (S::V, S::V, S::V) {
    let (mut lo, mut hi, mut p) = ([f64::NEG_INFINITY; 3], [f64::INFINITY; 3], [0.0; 3]);
    for k in (0..S::DIM).filter(|&k| periodic[k]) {
        (lo[k], hi[k], p[k]) = (min[k], max[k], max[k] - min[k]);
    }
    (S::from_array(lo), S::from_array(hi), S::from_array(p))
}

/// Vector operations the kernels need, on `DVec2` and `DVec3`.
pub trait Vector:
    Copy
    + Debug
    + Default
    + PartialEq
    + Send
    + Sync
    + Add<Output = Self>
    + Sub<Output = Self>
    + Mul<f64, Output = Self>
    + Neg<Output = Self>
    + AddAssign
    + SubAssign
    + serde::Serialize
    + serde::de::DeserializeOwned
    + 'static
{
    fn dot(self, o: Self) -> f64;
    fn length_squared(self) -> f64 {
        self.dot(self)
    }
    fn length(self) -> f64 {
        self.length_squared().sqrt()
    }
    fn is_finite(self) -> bool;
    /// Minimum-image correction of a separation between two positions that both lie in the
    /// periodic box (so each component is within one period): a component beyond half its
    /// `period` is moved back by one period (`half` = period/2; both 0 where not periodic).
    /// Comparisons, not `round()`, which is a library call on baseline x86-64.
    fn min_image(self, period: Self, half: Self) -> Self;
    /// Wraps a position that left the box [lo, hi) by less than one period back into it
    /// (`period` 0 on open axes, whose bounds are ±∞ for this purpose).
    fn wrap(self, lo: Self, hi: Self, period: Self) -> Self;
}

impl Vector for DVec2 {
    #[inline]
    fn dot(self, o: Self) -> f64 {
        DVec2::dot(self, o)
    }
    fn is_finite(self) -> bool {
        DVec2::is_finite(self)
    }
    #[inline]
    fn min_image(self, period: Self, half: Self) -> Self {
        let up = DVec2::select(self.cmpgt(half), period, DVec2::ZERO);
        let down = DVec2::select(self.cmplt(-half), period, DVec2::ZERO);
        self - up + down
    }
    #[inline]
    fn wrap(self, lo: Self, hi: Self, period: Self) -> Self {
        let up = DVec2::select(self.cmplt(lo), period, DVec2::ZERO);
        let down = DVec2::select(self.cmpge(hi), period, DVec2::ZERO);
        self + up - down
    }
}

impl Vector for DVec3 {
    #[inline]
    fn dot(self, o: Self) -> f64 {
        DVec3::dot(self, o)
    }
    fn is_finite(self) -> bool {
        DVec3::is_finite(self)
    }
    #[inline]
    fn min_image(self, period: Self, half: Self) -> Self {
        let up = DVec3::select(self.cmpgt(half), period, DVec3::ZERO);
        let down = DVec3::select(self.cmplt(-half), period, DVec3::ZERO);
        self - up + down
    }
    #[inline]
    fn wrap(self, lo: Self, hi: Self, period: Self) -> Self {
        let up = DVec3::select(self.cmplt(lo), period, DVec3::ZERO);
        let down = DVec3::select(self.cmpge(hi), period, DVec3::ZERO);
        self + up - down
    }
}

impl Vector for f64 {
    #[inline]
    fn dot(self, o: Self) -> f64 {
        self * o
    }
    fn is_finite(self) -> bool {
        f64::is_finite(self)
    }
    fn wrap(self, lo: Self, hi: Self, period: Self) -> Self {
        if self < lo {
            self + period
        } else if self >= hi {
            self - period
        } else {
            self
        }
    }
    fn min_image(self, period: Self, half: Self) -> Self {
        if self > half {
            self - period
        } else if self < -half {
            self + period
        } else {
            self
        }
    }
}

/// A spatial dimension.
pub trait Space: Copy + Debug + Default + Send + Sync + 'static {
    const DIM: usize;
    /// Position, velocity, force.
    type V: Vector;
    /// Angular velocity and torque (z component in 2D).
    type Ang: Vector;
    /// Orientation (angle in 2D, unit quaternion in 3D).
    type Rot: Copy + Debug + Default + PartialEq + Send + Sync + serde::Serialize + serde::de::DeserializeOwned + 'static;

    /// Moment of inertia of a grain over m r² (disk 1/2, solid sphere 2/5).
    const INERTIA_FACTOR: f64;

    fn from_array(a: [f64; 3]) -> Self::V;
    fn to_array(v: Self::V) -> [f64; 3];
    fn component(v: Self::V, k: usize) -> f64 {
        Self::to_array(v)[k]
    }
    /// ω × r: velocity of a point at offset r on a body spinning at ω.
    fn ang_cross(omega: Self::Ang, r: Self::V) -> Self::V;
    /// r × f: torque of a force f applied at offset r.
    fn torque(r: Self::V, f: Self::V) -> Self::Ang;
    fn identity_rot() -> Self::Rot;
    /// Orientation after spinning at ω for dt.
    fn rotate(rot: Self::Rot, omega: Self::Ang, dt: f64) -> Self::Rot;
    /// Orientation as a quaternion (2D: rotation about z), for output.
    fn rot_quat(rot: Self::Rot) -> [f64; 4];
    fn ang_array(a: Self::Ang) -> [f64; 3];
    /// An angular vector from its components (2D: the z component).
    fn ang_from_array(a: [f64; 3]) -> Self::Ang;
}

#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct D2;

#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct D3;

impl Space for D2 {
    const DIM: usize = 2;
    type V = DVec2;
    type Ang = f64;
    type Rot = f64;
    const INERTIA_FACTOR: f64 = 0.5;

    #[inline]
    fn from_array(a: [f64; 3]) -> DVec2 {
        DVec2::new(a[0], a[1])
    }
    #[inline]
    fn to_array(v: DVec2) -> [f64; 3] {
        [v.x, v.y, 0.0]
    }
    #[inline]
    fn ang_cross(omega: f64, r: DVec2) -> DVec2 {
        DVec2::new(-omega * r.y, omega * r.x)
    }
    #[inline]
    fn torque(r: DVec2, f: DVec2) -> f64 {
        r.x * f.y - r.y * f.x
    }
    fn identity_rot() -> f64 {
        0.0
    }
    #[inline]
    fn rotate(rot: f64, omega: f64, dt: f64) -> f64 {
        rot + omega * dt
    }
    fn rot_quat(rot: f64) -> [f64; 4] {
        let q = DQuat::from_rotation_z(rot);
        [q.w, q.x, q.y, q.z]
    }
    fn ang_array(a: f64) -> [f64; 3] {
        [0.0, 0.0, a]
    }
    #[inline]
    fn ang_from_array(a: [f64; 3]) -> f64 {
        a[2]
    }
}

impl Space for D3 {
    const DIM: usize = 3;
    type V = DVec3;
    type Ang = DVec3;
    type Rot = DQuat;
    const INERTIA_FACTOR: f64 = 0.4;

    #[inline]
    fn from_array(a: [f64; 3]) -> DVec3 {
        DVec3::from_array(a)
    }
    #[inline]
    fn to_array(v: DVec3) -> [f64; 3] {
        v.to_array()
    }
    #[inline]
    fn ang_cross(omega: DVec3, r: DVec3) -> DVec3 {
        omega.cross(r)
    }
    #[inline]
    fn torque(r: DVec3, f: DVec3) -> DVec3 {
        r.cross(f)
    }
    fn identity_rot() -> DQuat {
        DQuat::IDENTITY
    }
    /// q ← normalize(q + dt/2 · (0, ω) q): first order in ω dt, which is far below 1 at DEM
    /// steps, and free of the sine and cosine an exact rotation costs per grain and step.
    #[inline]
    fn rotate(rot: DQuat, omega: DVec3, dt: f64) -> DQuat {
        let h = 0.5 * dt;
        let dq = DQuat::from_xyzw(omega.x * h, omega.y * h, omega.z * h, 0.0) * rot;
        (rot + dq).normalize()
    }
    fn rot_quat(rot: DQuat) -> [f64; 4] {
        [rot.w, rot.x, rot.y, rot.z]
    }
    fn ang_array(a: DVec3) -> [f64; 3] {
        a.to_array()
    }
    #[inline]
    fn ang_from_array(a: [f64; 3]) -> DVec3 {
        DVec3::from_array(a)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn cross_products_agree_between_2d_and_3d() {
        let (w, r, f) = (1.5, DVec2::new(0.3, -0.7), DVec2::new(2.0, 0.5));
        let v2 = D2::ang_cross(w, r);
        let v3 = D3::ang_cross(DVec3::new(0.0, 0.0, w), r.extend(0.0));
        assert_eq!(v2.extend(0.0), v3);
        assert_eq!(D2::torque(r, f), D3::torque(r.extend(0.0), f.extend(0.0)).z);
    }

    #[test]
    fn quaternion_rotation_turns_by_omega_dt() {
        // A quarter turn about z in 10,000 small steps.
        let mut q = DQuat::IDENTITY;
        for _ in 0..10_000 {
            q = D3::rotate(q, DVec3::new(0.0, 0.0, std::f64::consts::PI), 0.5 / 10_000.0);
        }
        let x = q * DVec3::X;
        assert!((x - DVec3::Y).length() < 1e-6, "{x}");
    }
}

/// Where `p` lies relative to the 2D segment `a` → `b` (x and y of the arrays): `along` the
/// segment from `a` [m] (inside it for 0 < along < `length`), `ahead` of it [m] (signed,
/// positive on its left: the side of a → b turned counter-clockwise), and that left `normal`.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct SegmentFrame {
    pub along: f64,
    pub ahead: f64,
    pub length: f64,
    pub normal: [f64; 2],
}

pub fn segment_frame(a: [f64; 3], b: [f64; 3], p: [f64; 3]) -> SegmentFrame {
    let (tx, ty) = (b[0] - a[0], b[1] - a[1]);
    let length = tx.hypot(ty);
    let normal = [-ty / length, tx / length];
    let (dx, dy) = (p[0] - a[0], p[1] - a[1]);
    SegmentFrame {
        along: (dx * tx + dy * ty) / length,
        ahead: dx * normal[0] + dy * normal[1],
        length,
        normal,
    }
}

impl SegmentFrame {
    /// Between the segment's ends; `closed`: the ends themselves count.
    pub fn between_ends(&self, closed: bool) -> bool {
        if closed {
            (0.0..=self.length).contains(&self.along)
        } else {
            self.along > 0.0 && self.along < self.length
        }
    }
}
