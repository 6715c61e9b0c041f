//! DEM state as plain data: grains (structure of arrays), walls, the domain, parameters.

use crate::contact::ContactParams;
use crate::space::Space;

/// Grains, one entry per grain in every array. `id` is stable (outputs, history, spawn and
/// delete lists); storage indices may change.
#[derive(Clone, Debug, Default, PartialEq, serde::Serialize, serde::Deserialize)]
#[serde(bound = "")]
pub struct Grains<S: Space> {
    pub id: Vec<u64>,
    /// Centre [m].
    pub x: Vec<S::V>,
    /// Velocity [m/s].
    pub v: Vec<S::V>,
    /// Angular velocity [rad/s].
    pub omega: Vec<S::Ang>,
    pub rot: Vec<S::Rot>,
    /// [m]
    pub radius: Vec<f64>,
    /// Full mass [kg] (2D: per metre of thickness, ρπr²).
    pub mass: Vec<f64>,
    /// Hybrid scale 1 − w of mass and springs (Yue 2018 §3.5); 1 outside a hybrid zone.
    pub scale: Vec<f64>,
    /// Index into [`DemParams::materials`].
    pub material: Vec<u32>,
    /// Frozen grains take no force and move at their own velocity, unchanged by contacts:
    /// rough bases of benchmark beds (at rest), the driven plate of a shear cell. They push.
    pub frozen: Vec<bool>,
    /// External force on each grain [N], added every step (coupling, tests).
    pub external: Vec<S::V>,
}

impl<S: Space> Grains<S> {
    pub fn len(&self) -> usize {
        self.id.len()
    }

    pub fn is_empty(&self) -> bool {
        self.id.is_empty()
    }

    /// Storage index of the grain with stable id `id` (indices change when the pipeline
    /// re-sorts grains by cell for locality).
    pub fn index_of(&self, id: u64) -> Option<usize> {
        self.id.iter().position(|&x| x == id)
    }

    /// Reorders every array by `order` (new index k holds old grain `order[k]`).
    pub fn permute(&mut self, order: &[u32]) {
        fn apply<T: Copy>(v: &mut Vec<T>, order: &[u32]) {
            let old = std::mem::take(v);
            *v = order.iter().map(|&k| old[k as usize]).collect();
        }
        apply(&mut self.id, order);
        apply(&mut self.x, order);
        apply(&mut self.v, order);
        apply(&mut self.omega, order);
        apply(&mut self.rot, order);
        apply(&mut self.radius, order);
        apply(&mut self.mass, order);
        apply(&mut self.scale, order);
        apply(&mut self.material, order);
        apply(&mut self.frozen, order);
        apply(&mut self.external, order);
    }

    /// Adds a grain at rest; returns its index.
    pub fn push(&mut self, id: u64, x: S::V, radius: f64, mass: f64, material: u32) -> usize {
        self.id.push(id);
        self.x.push(x);
        self.v.push(S::V::default());
        self.omega.push(S::Ang::default());
        self.rot.push(S::identity_rot());
        self.radius.push(radius);
        self.mass.push(mass);
        self.scale.push(1.0);
        self.material.push(material);
        self.frozen.push(false);
        self.external.push(S::V::default());
        self.len() - 1
    }

    /// Mass of a grain of radius r and density ρ: ρπr² in 2D (per metre), ρ 4/3 π r³ in 3D.
    pub fn mass_of(radius: f64, density: f64) -> f64 {
        if S::DIM == 2 {
            density * std::f64::consts::PI * radius * radius
        } else {
            density * 4.0 / 3.0 * std::f64::consts::PI * radius.powi(3)
        }
    }
}

/// A boundary the grains cannot pass.
#[derive(Clone, Copy, Debug, PartialEq, serde::Serialize, serde::Deserialize)]
#[serde(bound = "")]
pub enum WallShape<S: Space> {
    /// Half-space boundary through `point`; grains stay on the side `normal` points to.
    Plane { point: S::V, normal: S::V },
    /// Inside of a circle (2D) or of a cylinder along z (3D): grains stay inside.
    Drum { center: S::V, radius: f64 },
    /// A line segment from `a` to `b` that grains cannot cross (in 3D, a thin rod): the
    /// pieces of silo bottoms and hoppers.
    Segment { a: S::V, b: S::V },
}

/// A wall, possibly scripted: it translates at `velocity` and a drum spins at `spin` about
/// its axis. The force the grains exert on it is recorded every step.
#[derive(Clone, Copy, Debug, PartialEq, serde::Serialize, serde::Deserialize)]
#[serde(bound = "")]
pub struct Wall<S: Space> {
    pub shape: WallShape<S>,
    /// Translation velocity [m/s].
    pub velocity: S::V,
    /// Angular velocity of a drum about its axis [rad/s] (z; counter-clockwise positive).
    pub spin: f64,
    /// Friction between grains and this wall.
    pub friction: f64,
    /// Force of the grains on the wall during the last step [N].
    pub load: S::V,
    /// The scene wall it comes from (a box makes one plane per face).
    pub id: usize,
}

impl<S: Space> Wall<S> {
    pub fn plane(point: S::V, normal: S::V, friction: f64) -> Self {
        let normal = normal * (1.0 / crate::space::Vector::length(normal));
        Wall {
            shape: WallShape::Plane { point, normal },
            velocity: S::V::default(),
            spin: 0.0,
            friction,
            load: S::V::default(),
            id: 0,
        }
    }

    pub fn segment(a: S::V, b: S::V, friction: f64) -> Self {
        Wall {
            shape: WallShape::Segment { a, b },
            velocity: S::V::default(),
            spin: 0.0,
            friction,
            load: S::V::default(),
            id: 0,
        }
    }

    /// The same wall in the x–y plane (for the 2D bodies).
    pub fn in_plane<T: Space>(w: &Wall<T>) -> Wall<S> {
        let p = |v: T::V| {
            let a = T::to_array(v);
            S::from_array([a[0], a[1], 0.0])
        };
        Wall {
            shape: match w.shape {
                WallShape::Plane { point, normal } => WallShape::Plane {
                    point: p(point),
                    normal: p(normal),
                },
                WallShape::Drum { center, radius } => WallShape::Drum { center: p(center), radius },
                WallShape::Segment { a, b } => WallShape::Segment { a: p(a), b: p(b) },
            },
            velocity: p(w.velocity),
            spin: w.spin,
            friction: w.friction,
            load: p(w.load),
            id: w.id,
        }
    }

    pub fn drum(center: S::V, radius: f64, friction: f64) -> Self {
        Wall {
            shape: WallShape::Drum { center, radius },
            velocity: S::V::default(),
            spin: 0.0,
            friction,
            load: S::V::default(),
            id: 0,
        }
    }
}

/// Domain of the grains: bounds, and which axes are periodic.
#[derive(Clone, Copy, Debug, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct Domain {
    pub min: [f64; 3],
    pub max: [f64; 3],
    pub periodic: [bool; 3],
}

impl Domain {
    pub fn length(&self, k: usize) -> f64 {
        self.max[k] - self.min[k]
    }

    /// The bounds and periods for [`Vector::wrap`]: the box on periodic axes; ±∞ and a
    /// period of 0 on open ones, which never wrap.
    pub fn wrap_box<S: Space>(&self) -> (S::V, S::V, S::V) {
        grains_grid::space::wrap_box::<S>(self.min, self.max, self.periodic)
    }
}

/// Everything that stays fixed during a step.
#[derive(Clone, Debug, PartialEq, serde::Serialize, serde::Deserialize)]
#[serde(bound = "")]
pub struct DemParams<S: Space> {
    pub materials: Vec<ContactParams>,
    pub gravity: S::V,
    pub domain: Domain,
    /// Verlet skin [m]: pairs within r_i + r_j + skin are listed; the list is rebuilt when a
    /// grain has moved more than skin/2 since the last build.
    pub skin: f64,
}

/// A complete DEM model: grains, walls, parameters.
#[derive(Clone, Debug, PartialEq, serde::Serialize, serde::Deserialize)]
#[serde(bound = "")]
pub struct DemState<S: Space> {
    pub grains: Grains<S>,
    pub walls: Vec<Wall<S>>,
    /// Rigid spheropolygons (2D only; empty in 3D).
    pub bodies: Vec<crate::bodies::Body>,
    pub params: DemParams<S>,
    /// Simulated time [s].
    pub time: f64,
}
