//! The file as written: serde structs, unknown fields refused, spans kept.

use serde::Deserialize;
use toml::Spanned;

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
pub struct RawScene {
    pub schema: Spanned<u32>,
    pub gravity: Option<Spanned<Vec<f64>>>,
    pub run: RawRun,
    pub domain: RawDomain,
    #[serde(default)]
    pub material: Vec<RawMaterial>,
    #[serde(default)]
    pub body: Vec<RawBody>,
    #[serde(default)]
    pub wall: Vec<RawWall>,
    #[serde(default)]
    pub rigid: Vec<RawRigid>,
    pub coupling: Option<RawCoupling>,
    pub mpm: Option<RawMpm>,
    pub oracle: Option<RawOracle>,
    pub output: Option<RawOutput>,
    pub bridge: Option<RawBridge>,
    pub synthetic: Option<RawSynthetic>,
}

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
pub struct RawRun {
    pub name: Option<String>,
    pub dimension: Spanned<u32>,
    pub dt: Spanned<f64>,
    pub steps: Option<Spanned<u64>>,
    pub duration: Option<Spanned<f64>>,
    pub seed: Option<u64>,
    pub threads: Option<Spanned<u32>>,
}

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
pub struct RawDomain {
    pub min: Spanned<Vec<f64>>,
    pub max: Spanned<Vec<f64>>,
    pub cell_size: Spanned<f64>,
    pub periodic: Option<Spanned<Vec<bool>>>,
}

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
pub struct RawMaterial {
    pub name: Spanned<String>,
    pub density: Spanned<f64>,
    pub dem: Option<RawDemMaterial>,
    pub mpm: Option<RawMpmMaterial>,
}

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
pub struct RawDemMaterial {
    pub radius: Spanned<f64>,
    pub radius_std: Option<Spanned<f64>>,
    pub stiffness_normal: Spanned<f64>,
    pub stiffness_tangential: Option<Spanned<f64>>,
    pub restitution: Option<Spanned<f64>>,
    pub damping: Option<Spanned<f64>>,
    pub friction: Spanned<f64>,
    pub cohesion_normal: Option<Spanned<f64>>,
    pub cohesion_tangential: Option<Spanned<f64>>,
}

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
pub struct RawMpmMaterial {
    pub young: Spanned<f64>,
    pub poisson: Spanned<f64>,
    pub friction_angle: Spanned<f64>,
    pub cohesion: Option<Spanned<f64>>,
    pub model: Option<Spanned<String>>,
    pub packing: Spanned<f64>,
    pub packing_critical: Option<Spanned<f64>>,
    pub chi: Option<Spanned<f64>>,
    pub xi: Option<Spanned<f64>>,
    pub friction_angle_2: Option<Spanned<f64>>,
    pub inertial_i0: Option<Spanned<f64>>,
    pub calibration: Option<Spanned<String>>,
}

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
pub struct RawMpm {
    pub points_per_axis: Option<Spanned<u32>>,
    pub kernel: Option<Spanned<String>>,
    pub transfer: Option<Spanned<String>>,
    pub flip: Option<Spanned<f64>>,
    pub domain_walls: Option<Spanned<String>>,
    pub initial_stress: Option<Spanned<String>>,
}

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
pub struct RawBody {
    pub material: Spanned<String>,
    pub model: Spanned<String>,
    pub shape: Spanned<String>,
    pub min: Option<Spanned<Vec<f64>>>,
    pub max: Option<Spanned<Vec<f64>>>,
    pub center: Option<Spanned<Vec<f64>>>,
    pub radius: Option<Spanned<f64>>,
    pub packing: Option<Spanned<String>>,
    pub frozen: Option<Spanned<bool>>,
    pub confining_pressure: Option<Spanned<f64>>,
    pub velocity: Option<Spanned<Vec<f64>>>,
}

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
pub struct RawWall {
    pub kind: Spanned<String>,
    pub point: Option<Spanned<Vec<f64>>>,
    pub normal: Option<Spanned<Vec<f64>>>,
    pub min: Option<Spanned<Vec<f64>>>,
    pub max: Option<Spanned<Vec<f64>>>,
    pub center: Option<Spanned<Vec<f64>>>,
    pub radius: Option<Spanned<f64>>,
    pub from: Option<Spanned<Vec<f64>>>,
    pub to: Option<Spanned<Vec<f64>>>,
    pub friction: Option<Spanned<f64>>,
    pub velocity: Option<Spanned<Vec<f64>>>,
    pub spin: Option<Spanned<f64>>,
    pub sticky: Option<bool>,
}

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
pub struct RawRigid {
    pub material: Spanned<String>,
    pub vertices: Spanned<Vec<Vec<f64>>>,
    pub radius: Option<Spanned<f64>>,
    pub motion: Option<Spanned<String>>,
    pub velocity: Option<Spanned<Vec<f64>>>,
    pub spin: Option<Spanned<f64>>,
}

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
pub struct RawCoupling {
    /// A count, or "auto".
    pub substeps: Option<Spanned<toml::Value>>,
    pub dem_dt: Option<Spanned<f64>>,
    pub weight: Option<Spanned<f64>>,
    pub discrete_layer: Option<Spanned<f64>>,
    pub hybrid_band: Option<Spanned<f64>>,
    pub discrete_base: Option<Spanned<f64>>,
    pub grain_transfer: Option<Spanned<String>>,
    pub quasi_static: Option<Spanned<f64>>,
    pub contact_radius: Option<Spanned<f64>>,
    pub contact_forces: Option<Spanned<String>>,
}

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
pub struct RawOracle {
    pub kind: Spanned<String>,
    pub every: Option<Spanned<u64>>,
    pub critical_packing: Option<Spanned<f64>>,
    pub centre: Option<Spanned<f64>>,
    pub half_width: Option<Spanned<f64>>,
    pub max_inertial: Option<Spanned<f64>>,
    pub c0: Option<Spanned<f64>>,
    pub c1: Option<Spanned<f64>>,
    pub c_l: Option<Spanned<f64>>,
    pub c_g: Option<Spanned<f64>>,
    pub band_distance: Option<Spanned<f64>>,
    pub packing: Option<Spanned<String>>,
    pub training: Option<Spanned<bool>>,
}

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
pub struct RawBridge {
    pub enabled: bool,
    pub settings: Option<Spanned<String>>,
}

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
pub struct RawOutput {
    pub frames_every: Option<u64>,
    pub checkpoint_every: Option<u64>,
}

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
pub struct RawSynthetic {
    pub participants: Option<Spanned<Vec<String>>>,
    pub dem_nodes: Option<Spanned<u64>>,
    pub mpm_nodes: Option<Spanned<u64>>,
    pub overlap: Option<Spanned<f64>>,
    pub vary: Option<Spanned<f64>>,
    pub checksum: Option<bool>,
    pub content: Option<Spanned<String>>,
}
