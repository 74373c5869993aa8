//! Criterion benches of the mean value coordinate warp (Argudo et al. 2017, §5.2): a 1024²
//! RGBA target filled from one 1024² source and from two sources (separately, and combined),
//! with contours of M = 100 points (the paper's simplified contour), on 1 and 2 threads.
//!
//! `cargo bench -p phloem-core --bench mvc`. Throughput is in target pixels per second.

mod common;

use std::hint::black_box;

use common::{load, pool};
use criterion::{criterion_group, criterion_main, BenchmarkId, Criterion, Throughput};
use phloem_core::image::Image;
use phloem_core::mvc::{warp, warp_combine, Point};

/// Contour points, the paper's simplified contour size.
const M: usize = 100;

/// A concave, tree-crown-like contour of `m` points around the image centre.
fn crown(m: usize, size: f64, phase: f64) -> Vec<Point> {
    (0..m)
        .map(|i| {
            let a = std::f64::consts::TAU * i as f64 / m as f64;
            let r = size * (0.36 + 0.06 * (7.0 * a + phase).sin() + 0.03 * (13.0 * a).cos());
            [size / 2.0 + r * a.cos(), size / 2.0 + r * a.sin()]
        })
        .collect()
}

fn rgba(rgb: &[f32]) -> Vec<f32> {
    rgb.chunks_exact(3)
        .flat_map(|p| [p[0], p[1], p[2], 1.0])
        .collect()
}

fn mvc(c: &mut Criterion) {
    let n = 1024usize;
    let a = rgba(&load("python/phloem/data/bark_douglas_fir.png", n as u32));
    let b = rgba(&load("tests/data/water.jpg", n as u32));
    let sa = Image::new("a", &a, n, n, 4).unwrap();
    let sb = Image::new("b", &b, n, n, 4).unwrap();
    let (ca, cb, target) = (
        crown(M, n as f64, 0.0),
        crown(M, n as f64, 1.3),
        crown(M, n as f64, 0.6),
    );
    let mut g = c.benchmark_group("mvc_1024x1024_rgba_m100");
    g.sample_size(10)
        .throughput(Throughput::Elements((n * n) as u64));
    for threads in [1, 2] {
        let p = pool(threads);
        g.bench_with_input(
            BenchmarkId::new("one_source", format!("{threads}_threads")),
            &threads,
            |bch, _| {
                bch.iter(|| {
                    p.install(|| black_box(warp(&[sa], &[&ca], &target, n, n, None).unwrap()))
                });
            },
        );
        g.bench_with_input(
            BenchmarkId::new("two_sources_separate", format!("{threads}_threads")),
            &threads,
            |bch, _| {
                bch.iter(|| {
                    p.install(|| {
                        black_box(warp(&[sa, sb], &[&ca, &cb], &target, n, n, None).unwrap())
                    })
                });
            },
        );
        g.bench_with_input(
            BenchmarkId::new("two_sources_combined", format!("{threads}_threads")),
            &threads,
            |bch, _| {
                bch.iter(|| {
                    p.install(|| {
                        black_box(
                            warp_combine(&[sa, sb], &[&ca, &cb], &target, &[0.4, 0.6], n, n, None)
                                .unwrap(),
                        )
                    })
                });
            },
        );
    }
    g.finish();
}

criterion_group!(benches, mvc);
criterion_main!(benches);
