//! Seeding around rigid bodies: a continuum body's points are not placed where a rigid body
//! is (within its swept outline and the points' contact radius), and only those are left out.

use glam::DVec2;
use grains_grid::D2;
use grains_grid::polygon::near;
use grains_mpm_service::setup;
use grains_service::zones::ZoneField;

#[test]
fn points_are_left_out_where_a_rigid_body_is_and_only_there() {
    // Fines among 25 pentagons, the bar above them.
    let path = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("../../../scenes/sdem_matrix_2d.toml");
    let scene = grains_protocol::scene::load(&path).expect("shipped scene");
    let r_p = scene.contact_radius();
    let covered = |x: DVec2| {
        scene.rigids.iter().any(|r| {
            let poly: Vec<DVec2> = r.vertices.iter().map(|&[x, y]| DVec2::new(x, y)).collect();
            near(&poly, x).gap < r.radius + r_p
        })
    };
    let (with, _) = setup::build::<D2>(&scene, &ZoneField::layered(&scene)).unwrap();
    let mut bare = scene.clone();
    bare.rigids.clear();
    let (without, _) = setup::build::<D2>(&bare, &ZoneField::layered(&bare)).unwrap();
    assert!(with.x.iter().all(|&x| !covered(x)), "a point seeded inside a body's reach");
    let kept: Vec<DVec2> = without.x.iter().copied().filter(|&x| !covered(x)).collect();
    assert_eq!(with.x, kept, "the points outside every body, in the same order");
    // The skeleton leaves voids: some points kept (855 of 5,320 when written), most left out.
    assert!(
        !kept.is_empty() && kept.len() < without.len(),
        "the pentagons cover part of the fines: {} of {}",
        kept.len(),
        without.len()
    );
}
