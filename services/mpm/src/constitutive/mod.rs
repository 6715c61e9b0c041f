//! Constitutive models, one file per model, each a set of plain functions of the state.

pub mod hencky_critical_state;
pub mod plasticity_drucker_prager;
