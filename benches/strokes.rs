//! Criterion benches of the strokes engine: fetching the candidate pieces of one target stroke
//! and scoring every transition the dynamic programme may take (the hot loop of
//! `phloem.strokes.edit`), on 1 and 2 threads.
//!
//! `cargo bench -p phloem-core --bench strokes`. The object is a 64 × 400 strip of the embedded
//! bark, opaque; 24 target samples 24 px apart along a quarter circle, 9 candidate source
//! positions each, each candidate paired with the 4 of the next sample the stretch bound
//! allows (as `benches/python/bench_strokes.py`'s main branch). Throughput is in pairs.

mod common;

use std::hint::black_box;

use common::pool;
use criterion::{criterion_group, criterion_main, BenchmarkId, Criterion, Throughput};
use phloem_core::image::Image;
use phloem_core::strokes::{fetch, pair_energies, PieceSpec};

const SAMPLES: usize = 24;
const CANDIDATES: usize = 9;
const STEP: f64 = 24.0;

fn strip() -> Vec<f32> {
    let rgb = common::load("python/phloem/data/bark_douglas_fir.png", 400);
    let (h, w) = (400, 64);
    let mut out = vec![0f32; h * w * 4];
    for y in 0..h {
        for x in 0..w {
            let o = (y * w + x) * 4;
            out[o..o + 3].copy_from_slice(&rgb[(y * 400 + x) * 3..(y * 400 + x) * 3 + 3]);
            out[o + 3] = 1.0;
        }
    }
    out
}

fn specs() -> Vec<PieceSpec> {
    let mut out = Vec::new();
    for i in 0..SAMPLES {
        let a = (i as f64 * STEP) / 300.0;
        let (target, tangent) = (
            [100.0 + 300.0 * a.sin(), 400.0 - 300.0 * a.cos()],
            [a.cos(), a.sin()],
        );
        for k in 0..CANDIDATES {
            let s = (i as f64 * STEP * 0.6 + (k as f64 - 4.0) * 0.3 * STEP).clamp(0.0, 399.0);
            out.push(PieceSpec {
                target,
                target_tangent: tangent,
                source: [32.0, s],
                source_tangent: [0.0, 1.0],
                half_length: STEP,
                max_half_width: 60.0,
                target_half_width: 0.0,
                target_half_width_slope: 0.0,
            });
        }
    }
    out
}

fn bench(c: &mut Criterion) {
    let data = strip();
    let src = Image::new("source", &data, 400, 64, 4).unwrap();
    let sp = specs();
    let pairs: Vec<(usize, usize)> = (0..SAMPLES - 1)
        .flat_map(|i| {
            (0..CANDIDATES).flat_map(move |a| {
                (1..=4)
                    .filter(move |d| a + d < CANDIDATES)
                    .map(move |d| (i * CANDIDATES + a, (i + 1) * CANDIDATES + a + d - 2))
            })
        })
        .collect();
    let mut g = c.benchmark_group("strokes");
    g.sample_size(10);
    for threads in [1, 2] {
        let p = pool(threads);
        g.throughput(Throughput::Elements(sp.len() as u64));
        g.bench_with_input(
            BenchmarkId::new("fetch_pieces", threads),
            &threads,
            |b, _| {
                b.iter(|| p.install(|| black_box(fetch(&src, &sp).unwrap())));
            },
        );
        let pieces = fetch(&src, &sp).unwrap();
        g.throughput(Throughput::Elements(pairs.len() as u64));
        g.bench_with_input(
            BenchmarkId::new("pair_energies", threads),
            &threads,
            |b, _| {
                b.iter(|| p.install(|| black_box(pair_energies(&pieces, &pairs).unwrap())));
            },
        );
    }
    g.finish();
}

criterion_group!(benches, bench);
criterion_main!(benches);
