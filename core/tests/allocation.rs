//! The hot path allocates nothing: a counting global allocator around model inference and pose
//! compensation, by the reference model and by its fused serving form.

use std::alloc::{GlobalAlloc, Layout, System};
use std::cell::Cell;

mod common;

use hexacomp_core::Geometry;
use hexacomp_core::compensator::{compensate_pose, compensate_poses};
use hexacomp_core::fused::FusedModel;
use hexacomp_core::model::{Model, NetworkInput, Networks, Provenance};
use hexacomp_core::network::{Network, Normalisation};
use hexacomp_core::sampling::{SamplerOptions, WorkspaceSampler};

struct Counting;

thread_local! {
    /// Allocations made by the current thread (tests run in parallel threads).
    static ALLOCATIONS: Cell<usize> = const { Cell::new(0) };
}

fn allocations() -> usize {
    ALLOCATIONS.with(Cell::get)
}

unsafe impl GlobalAlloc for Counting {
    unsafe fn alloc(&self, layout: Layout) -> *mut u8 {
        ALLOCATIONS.with(|c| c.set(c.get() + 1));
        unsafe { System.alloc(layout) }
    }
    unsafe fn dealloc(&self, ptr: *mut u8, layout: Layout) {
        unsafe { System.dealloc(ptr, layout) }
    }
}

#[global_allocator]
static GLOBAL: Counting = Counting;

#[test]
fn the_counter_sees_allocations() {
    let before = allocations();
    let v = std::hint::black_box(vec![1u8; 10]);
    assert!(allocations() > before);
    drop(v);
}

#[test]
fn inference_and_compensation_allocate_nothing() {
    let g = Geometry::prototype();
    let network = |outputs| {
        let count = Network::weight_count(13, outputs);
        Network::from_weights(
            13,
            outputs,
            (0..count).map(|i| (i as f64).sin() * 0.01).collect(),
        )
        .unwrap()
    };
    let model = |networks| Model {
        networks,
        input: NetworkInput::Equivalent,
        normalisation: Normalisation {
            mean: [355.0; 6],
            span: [140.0; 6],
        },
        training_range: [[280.0, 430.0]; 6],
        correction_bounds: [[-2.0, 2.0]; 6],
        geometry: g.fingerprint(),
        provenance: Provenance::default(),
        // With an uncertainty: every compensated point computes it too.
        uncertainty: Some(common::uncertainty()),
    };
    let models = [
        model(Networks::Coupled(network(6))),
        model(Networks::Decoupled((0..6).map(|_| network(1)).collect())),
    ];
    let poses = WorkspaceSampler::new(&g, 1, SamplerOptions::default())
        .unwrap()
        .samples(1000)
        .unwrap();
    for m in &models {
        // The serving form is built once at load (that allocates); evaluating it must not, nor
        // its way back to the reference at a point whose correction sits on a bound.
        let fused = FusedModel::new(m);
        let at_a_bound = {
            let q = hexacomp_core::inverse_kinematics(&g, &poses[0]).lengths;
            let c = m.raw_corrections(&q)[0];
            let mut bounded = m.clone();
            bounded.correction_bounds[0] = [c - 1.0, c];
            FusedModel::new(&bounded)
        };
        let before = allocations();
        let mut checksum = 0.0;
        for pose in &poses {
            checksum += compensate_pose(&g, Some(m), pose).legs[0];
            checksum += compensate_pose(&g, Some(&fused), pose).legs[0];
        }
        checksum += compensate_pose(&g, Some(&at_a_bound), &poses[0]).legs[0];
        // In pairs, as the service computes a batch: by the fused form, by the reference, and
        // by the way back to the reference.
        let mut batch = [compensate_pose(&g, Some(&fused), &poses[0]); 8];
        for chunk in poses.chunks(8) {
            compensate_poses(&g, Some(&fused), chunk, &mut batch);
            checksum += batch[0].legs[0];
            compensate_poses(&g, Some(m), chunk, &mut batch);
            checksum += batch[1].legs[0];
        }
        compensate_poses(&g, Some(&at_a_bound), &[poses[0], poses[0]], &mut batch);
        checksum += batch[1].legs[0];
        let after = allocations();
        assert!(checksum.is_finite());
        assert_eq!(
            after - before,
            0,
            "{} allocations in 1000 compensations",
            after - before
        );
    }
}
