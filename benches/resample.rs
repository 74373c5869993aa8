//! Criterion bench of resampling a polyline to a constant edge length (Sibbing et al. 2010,
//! §4.1), as `Branch.resample` does for every branch of a traced skeleton: a pixel staircase of
//! 4000 points (a traced centre line, diagonal steps included) at `h` = 1 px (the measures' and
//! the smoothing's step) and 3 px (a bending model's step).
//!
//! `cargo bench -p phloem-core --bench resample`. Throughput is in input points per second.

use std::hint::black_box;

use criterion::{criterion_group, criterion_main, Criterion, Throughput};
use phloem_core::resample::resample;

const POINTS: usize = 4000;

/// A centre line on the pixel grid: unit and diagonal steps that wander slowly.
fn staircase() -> (Vec<[f64; 2]>, Vec<f64>) {
    let (mut x, mut y, mut a) = (0.0f64, 0.0f64, 0.3f64);
    let mut pts = Vec::with_capacity(POINTS);
    let mut cum = Vec::with_capacity(POINTS);
    let mut s = 0.0;
    for i in 0..POINTS {
        pts.push([x, y]);
        cum.push(s);
        a += 0.02 * ((i as f64) * 0.013).sin();
        let (dx, dy) = (a.cos().round(), a.sin().round());
        let (dx, dy) = if dx == 0.0 && dy == 0.0 {
            (1.0, 0.0)
        } else {
            (dx, dy)
        };
        x += dx;
        y += dy;
        s += dx.hypot(dy);
    }
    (pts, cum)
}

fn resampling(c: &mut Criterion) {
    let (pts, cum) = staircase();
    let total = cum[cum.len() - 1];
    let mut group = c.benchmark_group("resample");
    group.throughput(Throughput::Elements(POINTS as u64));
    for h in [1.0, 3.0] {
        let count = (total / h).floor() as usize + 1;
        group.bench_function(format!("staircase_{POINTS}_h{h}"), |b| {
            b.iter(|| resample(black_box(&pts), black_box(&cum), count, h).unwrap());
        });
    }
    group.finish();
}

criterion_group!(benches, resampling);
criterion_main!(benches);
