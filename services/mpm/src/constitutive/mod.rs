//! Constitutive models, one file per model, each a set of plain functions of the state.

pub mod plasticity_drucker_prager;
