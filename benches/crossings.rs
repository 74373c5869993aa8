//! Criterion bench of the planarity test of branching growth (Sibbing et al. 2010, §4.4):
//! a blocked tip's worst case, every one of 3099 candidate extensions of 4 edges (the traced
//! retina's candidate count) against 60 nearby segments, none of which the candidates cross,
//! so no early exit helps; and the common case, the 2 best candidates.
//!
//! `cargo bench -p phloem-core --bench crossings`. Throughput is in edge-segment tests per second.

use std::hint::black_box;

use criterion::{criterion_group, criterion_main, Criterion, Throughput};
use phloem_core::crossings::polylines_crossing;

const EDGES: usize = 4;
const SEGMENTS: usize = 60;

/// `n` fans of 4 edges from the origin, 3 px each, turning a little per edge.
fn paths(n: usize) -> Vec<f64> {
    let mut out = Vec::with_capacity(n * (EDGES + 1) * 2);
    for c in 0..n {
        let (mut x, mut y) = (0.0f64, 0.0f64);
        let mut a = (c as f64 / n as f64 - 0.5) * 2.0;
        out.extend([x, y]);
        for _ in 0..EDGES {
            a += 0.05;
            x += 3.0 * a.cos();
            y += 3.0 * a.sin();
            out.extend([x, y]);
        }
    }
    out
}

/// Short segments on a ring 20-30 px out, beyond the candidates' 12 px reach.
fn segments() -> Vec<f64> {
    (0..SEGMENTS)
        .flat_map(|i| {
            let t = i as f64 / SEGMENTS as f64 * std::f64::consts::TAU;
            let (r0, r1) = (20.0 + (i % 3) as f64, 30.0);
            [r0 * t.cos(), r0 * t.sin(), r1 * t.cos(), r1 * t.sin()]
        })
        .collect()
}

fn crossings(c: &mut Criterion) {
    let segs = segments();
    let mut group = c.benchmark_group("polylines_crossing");
    for (name, n) in [("all_3099_candidates", 3099), ("best_2", 2)] {
        let p = paths(n);
        assert!(!polylines_crossing(&p, EDGES + 1, &segs)
            .unwrap()
            .iter()
            .any(|&h| h));
        group.throughput(Throughput::Elements((n * EDGES * SEGMENTS) as u64));
        group.bench_function(name, |b| {
            b.iter(|| polylines_crossing(black_box(&p), EDGES + 1, black_box(&segs)).unwrap());
        });
    }
    group.finish();
}

criterion_group!(benches, crossings);
criterion_main!(benches);
