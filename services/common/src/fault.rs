//! Fault injection, read from the environment once, at the edge: a deliberately broken build
//! at run time, so that the test showing `grains validate --quick` failing on a broken contact
//! law needs no second build. The solver libraries take the result as a parameter.

/// `GRAINS_FAULT=restitution-damping-x2`: 2, the factor on the damping the DEM derives from a
/// restitution coefficient (`grains_dem::ContactParams::damping_scale`); 1 otherwise. Read
/// once per process.
pub fn restitution_damping_scale() -> f64 {
    static SCALE: std::sync::OnceLock<f64> = std::sync::OnceLock::new();
    *SCALE.get_or_init(|| match std::env::var("GRAINS_FAULT").as_deref() {
        Ok("restitution-damping-x2") => 2.0,
        _ => 1.0,
    })
}
