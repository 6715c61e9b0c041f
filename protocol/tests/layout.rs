//! Pins the wire layouts that `protocol/README.md` promises to external participants.
//! A change here is a protocol change: bump `PROTOCOL_VERSION` and the README with it.

use grains_protocol::wire::*;
use std::mem::{align_of, offset_of, size_of};

macro_rules! check_layout {
    ($ty:ty, size $size:expr, $( $field:ident @ $off:expr ),* $(,)?) => {{
        assert_eq!(size_of::<$ty>(), $size, "size of {}", stringify!($ty));
        assert_eq!(align_of::<$ty>(), 8, "alignment of {}", stringify!($ty));
        $( assert_eq!(offset_of!($ty, $field), $off, "offset of {}::{}", stringify!($ty), stringify!($field)); )*
    }};
}

#[test]
fn wire_layouts_match_the_spec() {
    check_layout!(StepHeader, size 80, protocol_version @ 0, sender @ 4, step @ 8, time @ 16,
        dt @ 24, checksum @ 32, flags @ 40, run_id @ 48);
    check_layout!(Hello, size 64, magic @ 0, scene_hash @ 8, protocol_version @ 16, role @ 20,
        pid @ 24, flags @ 28, run_id @ 32);
    check_layout!(Welcome, size 64, magic @ 0, scene_hash @ 8, protocol_version @ 16, role @ 20,
        pid @ 24, verdict @ 28, run_id @ 32);
    assert_eq!(size_of::<StepBegin>(), 8);
    assert_eq!(offset_of!(StepBegin, substeps), 4);
    check_layout!(RasterNode, size 40, node @ 0, mass @ 8, momentum @ 16);
    check_layout!(NodeVelocity, size 32, node @ 0, velocity @ 8);
    check_layout!(ZoneCell, size 24, cell @ 0, zone @ 8, _pad @ 12, distance @ 16);
    check_layout!(SpawnGrain, size 64, id @ 0, radius @ 8, position @ 16, velocity @ 40);
    check_layout!(SpawnPoint, size 120, id @ 0, volume @ 8, mass @ 16, position @ 24,
        velocity @ 48, stress @ 72);
    check_layout!(EpochItem, size 112, id @ 0, radius @ 8, mass @ 16, share @ 24, flags @ 32,
        position @ 40, velocity @ 64, plastic_strain @ 88, plastic_rate @ 96, pressure @ 104);
    check_layout!(NodeStress, size 56, node @ 0, stress @ 8);
    check_layout!(PointScale, size 16, id @ 0, factor @ 8);
    check_layout!(Summary, size 104, role @ 0, status @ 4, step @ 8, time @ 16, n_items @ 24,
        n_nodes @ 32, mass @ 40, momentum @ 48, kinetic_energy @ 72, checksum @ 80,
        compute_ns @ 88, wait_ns @ 96);
    check_layout!(Control, size 24, seq @ 0, command @ 8, key @ 12, value @ 16);
    check_layout!(ViewPoint, size 72, id @ 0, position @ 8, velocity @ 32, size @ 56, pressure @ 64);
    check_layout!(Ack, size 32, seq @ 0, step @ 8, command @ 16, status @ 20, key @ 24, _pad @ 28);
    check_layout!(BodyReach, size 40, id @ 0, center @ 8, reach @ 32);
    check_layout!(ContactPoint, size 80, index @ 0, id @ 8, position @ 16, velocity @ 40, mass @ 64, radius @ 72);
    check_layout!(PointForce, size 32, index @ 0, force @ 8);
}

#[test]
fn hello_magic_reads_grains() {
    assert_eq!(&grains_protocol::HELLO_MAGIC.to_le_bytes(), b"GRAINS\0\0");
}

#[test]
fn set_parameters_round_trip_through_their_codes_and_names() {
    use grains_protocol::wire::Param;
    for p in [
        Param::Gravity { axis: 0 },
        Param::Gravity { axis: 2 },
        Param::WallVelocity { wall: 0, axis: 1 },
        Param::WallVelocity { wall: 37, axis: 2 },
    ] {
        assert_eq!(Param::from_code(p.code()), Some(p));
        assert_eq!(Param::parse(&p.name()), Some(p));
    }
    assert_eq!(Param::Gravity { axis: 1 }.code(), 1 + 1);
    assert_eq!(Param::WallVelocity { wall: 2, axis: 0 }.code(), 16 + 8);
    for bad in [0, 4, 15, 19, 23] {
        assert_eq!(Param::from_code(bad), None, "code {bad}");
    }
    for bad in [
        "gravity",
        "gravity.w",
        "wall.x.velocity.y",
        "wall.1.speed.x",
        "wall.-1.velocity.x",
        "wall.99999.velocity.x",
    ] {
        assert_eq!(Param::parse(bad), None, "{bad}");
    }
}
