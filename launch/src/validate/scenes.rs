//! The scenes the validation runs, with the geometry it reads their results by. These must
//! agree with the files in `scenes/` (their headers say so too).

/// The column collapse (Yue 2018 §5, Lube et al. 2005): a column L₀ wide against the wall at
/// x = 0, standing on a glued floor row.
pub mod column {
    pub const DEM: &str = "column_collapse_2d.toml";
    pub const HYBRID: &str = "column_collapse_hybrid_2d.toml";
    pub const MPM: &str = "column_collapse_mpm_2d.toml";
    /// The pour every column is cut from.
    pub const PACKING: &str = "column_packing_2d.toml";
    /// Column width L₀ [m].
    pub const L0: f64 = 0.04;
    /// Bottom of the columns, above the floor row [m].
    pub const BOTTOM: f64 = 0.0015;
    /// Mean grain diameter [m].
    pub const D: f64 = 0.001;
}

/// The silo (Yue 2018 §5.2): a 40 mm bin over an orifice in its bottom at y = 60 mm.
pub mod silo {
    pub const SCENE: &str = "silo_hybrid_2d.toml";
    pub const SMALL_SCENE: &str = "silo_small_orifice_2d.toml";
    /// The silo's bottom [m] and the orifice's centre [m].
    pub const BOTTOM: f64 = 0.06;
    pub const CENTRE: f64 = 0.02;
    /// The scene's fill over the bottom [m], and the lattice poured for it over its own
    /// height (a lattice settles to about 3/4 of it).
    pub const FILL: f64 = 0.06;
    pub const LATTICE: f64 = 4.0 / 3.0;
    /// Mean grain diameter [m].
    pub const D: f64 = 0.001;
}

/// Plate indentation (Chen 2021 §6.3): a bed [`WIDTH`] wide between walls, cut at [`TOP`]
/// from a poured packing (the DEM) or filled to it (the continuum), and a plate scripted down
/// into its middle (`rigid.0` of the DEM scene, `rigid.1` of the continuum's, after the floor).
pub mod plate {
    pub const DEM: &str = "plate_indentation_2d.toml";
    pub const MPM: &str = "plate_indentation_mpm_2d.toml";
    /// Chen's hybrid (`oracle.kind = "shear_band"`) on its own bed, with a segment wall for
    /// the plate; run also as a DEM from its packing and as a continuum.
    pub const HYBRID: &str = "plate_indentation_hybrid_2d.toml";
    /// The bed's width and its top [m] (the continuum scene's body.0.max).
    pub const WIDTH: f64 = 0.16;
    pub const TOP: f64 = 0.04;
    /// The plate: its width B, its outline's half height (the centre of mass above its bottom),
    /// its centre's x [m], its speed [m/s] (the scenes' own).
    pub const B: f64 = 0.016;
    pub const HALF_HEIGHT: f64 = 0.004;
    pub const CENTRE: f64 = 0.08;
    /// How deep the plate goes: half its width [m].
    pub const DEPTH: f64 = 0.008;
}

/// The turning drum.
pub mod drum {
    pub const SCENE: &str = "drum_hybrid_2d.toml";
    pub const CENTRE: [f64; 2] = [0.05, 0.05];
    pub const RADIUS: f64 = 0.045;
}

/// Rigid bodies in contact with a continuum (Jiang 2020 §5).
pub mod sdem {
    /// §5.1.1: an MPM disk hits a rigid disk (the MPM body first, the rigid disk `rigid.0`).
    pub const DISK: &str = "sdem_disk_impact_2d.toml";
    /// The soft disk's moduli are the hard one's over this.
    pub const SOFTER: f64 = 10.0;
    /// §5.1.2: the same MPM disk dropped on a fixed slab (`rigid.0`).
    pub const DROP: &str = "sdem_disk_drop_2d.toml";
    /// §5.2.2: the block launched along a fixed slab (`rigid.0`), and when its landing's
    /// bounces are over [s].
    pub const SLIDE: &str = "sdem_block_slide_2d.toml";
    pub const SLIDE_WINDOW: f64 = 0.08;
    /// §5.2.1: an MPM block at rest on a fixed slab (`rigid.0`), and its grids [m].
    pub const BLOCK: &str = "sdem_block_rest_2d.toml";
    pub const GRIDS: [f64; 4] = [0.002, 0.0025, 0.003, 0.004];
    /// §5.3: MPM sand in a silo on two fixed slabs (`rigid.0` left, `rigid.1` right of the
    /// orifice; top faces at the silo's bottom [`super::silo::BOTTOM`], centred on
    /// [`super::silo::CENTRE`], sphero-radius [`SLAB_RADIUS`]), and its orifices [m].
    pub const SILO: &str = "sdem_silo_2d.toml";
    pub const SLAB_RADIUS: f64 = 0.0005;
    pub const ORIFICES: [f64; 5] = [0.004, 0.006, 0.008, 0.010, 0.012];
    /// §5.4: an MPM bar hits a rigid bar (`rigid.0`, a rectangle of [`ROD_LENGTH`] by
    /// [`ROD_LENGTH`] swept by [`SLAB_RADIUS`]), on these grids [m].
    pub const ROD: &str = "sdem_rod_2d.toml";
    pub const ROD_LENGTH: f64 = 0.01;
    pub const ROD_GRIDS: [f64; 6] = [0.001, 0.002, 0.0025, 0.004, 0.005, 0.01];
    /// §7: rigid pentagons with MPM fines (`body.0`, a box from the floor) compressed by a
    /// scripted bar (the last rigid body) starting [`MATRIX_GAP`] above them [m]; the fines'
    /// heights [m].
    pub const MATRIX: &str = "sdem_matrix_2d.toml";
    pub const MATRIX_GAP: f64 = 0.001;
    pub const FILLS: [f64; 3] = [0.015, 0.03, 0.045];
}
