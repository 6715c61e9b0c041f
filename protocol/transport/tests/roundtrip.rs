//! Both transports carry messages of changing length intact, in order, written and read in
//! place; an empty wait times out instead of blocking; the iceoryx2 one leaves no file behind.

use grains_protocol::names::DEM_RASTER;
use grains_protocol::wire::{RasterNode, StepHeader};
use grains_transport::{Publisher, Subscriber, Transport, inproc::InProc, ipc};
use std::time::{Duration, Instant};

const LENGTHS: [usize; 5] = [10, 1_000, 300_000, 5, 1_000_000];

fn node(step: u64, j: usize) -> RasterNode {
    RasterNode {
        node: j as u64 * 3,
        mass: step as f64 + j as f64 * 0.5,
        momentum: [j as f64, -(step as f64), 1.0 / (1.0 + j as f64)],
    }
}

fn exchange<T: Transport>(tx: &T, rx: &T) {
    let mut sub = rx.subscriber::<RasterNode, StepHeader>(&DEM_RASTER).unwrap();
    let mut publ = tx.publisher::<RasterNode, StepHeader>(&DEM_RASTER, 16).unwrap();
    assert_eq!(publ.subscriber_count(), 1);
    assert_eq!(sub.publisher_count(), 1);

    let t = Instant::now();
    assert!(
        sub.receive(Duration::from_millis(50), |_, _| ()).unwrap().is_none(),
        "nothing was sent"
    );
    assert!(
        t.elapsed() >= Duration::from_millis(45),
        "an empty receive must wait for its timeout"
    );

    for (k, &n) in LENGTHS.iter().enumerate() {
        let step = k as u64 + 1;
        publ.publish(n, |h, out| {
            h.step = step;
            for (j, slot) in out.iter_mut().enumerate() {
                *slot = node(step, j);
            }
        })
        .unwrap();
        let ok = sub
            .receive(Duration::from_secs(5), |h, data| {
                h.step == step && data.len() == n && data.iter().enumerate().all(|(j, x)| *x == node(step, j))
            })
            .unwrap();
        assert_eq!(ok, Some(true), "message of step {step} with {n} elements");
    }
}

#[test]
fn inproc_carries_growing_and_shrinking_messages() {
    let bus = InProc::new();
    exchange(&bus, &bus.clone());
}

#[test]
fn iceoryx2_carries_growing_and_shrinking_messages_and_cleans_up() {
    let run_id = format!("test-roundtrip-{}", std::process::id());
    {
        let a = ipc::Iceoryx2::join(&run_id, "grains-dem", std::sync::Arc::new(|| false)).unwrap();
        let b = ipc::Iceoryx2::join(&run_id, "grains-coupler", std::sync::Arc::new(|| false)).unwrap();
        assert!(!ipc::run_files(&run_id).is_empty(), "a live run has files under its prefix");
        exchange(&a, &b);
        assert!(a.dead_peers(&|_| false).is_empty());
    }
    ipc::remove_run_files(&run_id);
    assert_eq!(ipc::run_files(&run_id), Vec::<std::path::PathBuf>::new());
}
