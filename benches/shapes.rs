//! Criterion benches of the boundary-patch shape optimiser: label maps of the embedded bark
//! (gray, blurred, cut into three labels at its tertiles) synthesised at 256² and 512², layered
//! and joint, on 2 threads, and the Eq. 3.9 similarity of two such maps.
//!
//! `cargo bench -p phloem-core --bench shapes`. Throughput is in output pixels per second. The
//! same workloads from Python (k-means labels): `python benches/bench_shapes.py`.

mod common;

use std::hint::black_box;

use common::{load, pool};
use criterion::{criterion_group, criterion_main, BenchmarkId, Criterion, Throughput};
use phloem_core::shapes::{
    similarity, synthesize_labels, LabelMap, Method, Rotations, ShapeParams,
};

/// The embedded bark at 256², box-blurred gray cut at its tertiles into labels 0..3.
fn bark_labels() -> LabelMap {
    let n = 256;
    let rgb = load("python/phloem/data/bark_douglas_fir.png", n as u32);
    let gray: Vec<f32> = rgb
        .chunks_exact(3)
        .map(|p| p.iter().sum::<f32>() / 3.0)
        .collect();
    let r = 3isize;
    let mut blur = vec![0f32; n * n];
    for y in 0..n {
        for x in 0..n {
            let (mut s, mut c) = (0.0, 0.0);
            for dy in -r..=r {
                for dx in -r..=r {
                    let (yy, xx) = (y as isize + dy, x as isize + dx);
                    if yy >= 0 && xx >= 0 && (yy as usize) < n && (xx as usize) < n {
                        s += gray[yy as usize * n + xx as usize];
                        c += 1.0;
                    }
                }
            }
            blur[y * n + x] = s / c;
        }
    }
    let mut sorted = blur.clone();
    sorted.sort_by(f32::total_cmp);
    let (t1, t2) = (sorted[n * n / 3], sorted[2 * n * n / 3]);
    let data = blur
        .iter()
        .map(|&v| u8::from(v >= t1) + u8::from(v >= t2))
        .collect();
    LabelMap { data, h: n, w: n }
}

fn label_maps(c: &mut Criterion) {
    let ex = bark_labels();
    let mut g = c.benchmark_group("shapes");
    g.sample_size(10);
    let pool = pool(2);
    for size in [256usize, 512] {
        g.throughput(Throughput::Elements((size * size) as u64));
        for (name, method) in [("layered", Method::Layered), ("joint", Method::Joint)] {
            g.bench_with_input(BenchmarkId::new(name, size), &size, |bch, &size| {
                bch.iter(|| {
                    pool.install(|| {
                        let p = ShapeParams::default();
                        black_box(
                            synthesize_labels(&ex, 3, size, size, method, None, &p, None).unwrap(),
                        )
                    })
                });
            });
        }
    }
    g.finish();
}

fn similarity_bench(c: &mut Criterion) {
    let ex = bark_labels();
    let out = synthesize_labels(
        &ex,
        3,
        256,
        256,
        Method::Joint,
        None,
        &ShapeParams::default(),
        None,
    )
    .unwrap();
    let mut g = c.benchmark_group("shape_similarity");
    g.sample_size(10);
    g.throughput(Throughput::Elements((256 * 256) as u64));
    let pool = pool(2);
    g.bench_function("256", |bch| {
        bch.iter(|| pool.install(|| black_box(similarity(&ex, &out, 7, Rotations::All).unwrap())));
    });
    g.finish();
}

criterion_group!(benches, label_maps, similarity_bench);
criterion_main!(benches);
