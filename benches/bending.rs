//! Criterion bench of the bending model's per-candidate terms in one growth step (Sibbing et
//! al. 2010, §4.2), at the traced brain vessels' sizes: 11171 candidates, a history of
//! `k + 1 = 4` elements, `P = 3` heading-change windows per candidate, 16 bins.
//!
//! `cargo bench -p phloem-core --bench bending`. Throughput is in candidates per second.

use std::hint::black_box;

use criterion::{criterion_group, criterion_main, Criterion, Throughput};
use phloem_core::bending::{dist_columns, histogram_moves, turn_bins};

const C: usize = 11171;
const L: usize = 4;
const P: usize = 3;
const BINS: usize = 16;

/// A deterministic spread of values in about [-2, 2].
fn wave(n: usize, f: f64) -> Vec<f64> {
    (0..n).map(|i| 2.0 * ((i as f64) * f).sin()).collect()
}

fn bending(c: &mut Criterion) {
    let cols = wave(L * C, 0.37);
    let y = [0.1, -0.2, 0.05, 0.3];
    let turns = wave(P * C, 0.11);
    let bins = turn_bins(&turns, BINS).unwrap();
    let u: Vec<f64> = (0..BINS).map(|i| 0.01 * (i as f64) - 0.05).collect();
    let uu: f64 = u.iter().map(|v| v * v).sum();
    let mut group = c.benchmark_group("bending");
    group.throughput(Throughput::Elements(C as u64));
    group.bench_function("dist_columns", |b| {
        b.iter(|| dist_columns(black_box(&cols), black_box(&y)).unwrap());
    });
    group.bench_function("turn_bins", |b| {
        b.iter(|| turn_bins(black_box(&turns), BINS).unwrap());
    });
    group.bench_function("histogram_moves", |b| {
        b.iter(|| histogram_moves(black_box(&u), uu, 0.01, 500.0, black_box(&bins), P).unwrap());
    });
    group.finish();
}

criterion_group!(benches, bending);
criterion_main!(benches);
