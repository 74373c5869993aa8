//! Criterion benches of the gradient-domain solvers: Poisson blending of 256² and 511² bark
//! squares and a 511² disk into a 1024² water photo (the issues' workloads, RGB, tol 1e-6) on 1
//! and 2 threads, smooth field interpolation over a 128² disk, and the sampling maps of one
//! deformed river-sized fragment (radius 67 px, the branching render's per-fragment warp).
//!
//! `cargo bench -p phloem-core --bench blend`. Throughput is in region pixels per second;
//! iterations and residuals are printed once per workload.

mod common;

use std::hint::black_box;

use common::{load, pool};
use criterion::{criterion_group, criterion_main, BenchmarkId, Criterion, Throughput};
use phloem_core::deform::{fragment_maps, Placement};
use phloem_core::field::{interpolate_field, FieldParams};
use phloem_core::image::Image;
use phloem_core::poisson::{seamless, BlendInput, BlendParams};

fn poisson(c: &mut Criterion) {
    let dst = load("tests/data/water.jpg", 1024);
    for (n, shape) in [(256usize, "square"), (511, "square"), (511, "disk")] {
        let src = load("python/phloem/data/bark_douglas_fir.png", n as u32);
        let mid = (n as f64 - 1.0) / 2.0;
        // The whole square but its one-pixel rim, as cv2.seamlessClone uses it, or the disk
        // inside that rim.
        let mask: Vec<bool> = (0..n * n)
            .map(|i| {
                let (y, x) = (i / n, i % n);
                if shape == "square" {
                    (1..n - 1).contains(&y) && (1..n - 1).contains(&x)
                } else {
                    (y as f64 - mid).powi(2) + (x as f64 - mid).powi(2)
                        < (n as f64 / 2.0 - 1.0).powi(2)
                }
            })
            .collect();
        let input = BlendInput {
            src: Image::new("src", &src, n, n, 3).unwrap(),
            dst: Image::new("dst", &dst, 1024, 1024, 3).unwrap(),
            mask: &mask,
            offset: ((512 - n / 2) as i64, (512 - n / 2) as i64),
            fixed: None,
            labels: None,
        };
        let params = BlendParams::default();
        let b = seamless(&input, &params).unwrap();
        println!(
            "poisson {n}x{n} {shape} rgb into 1024x1024: {} unknowns, {} iterations, residual {:.2e}",
            b.unknowns, b.iterations, b.residual
        );
        // The squares keep their group names so criterion baselines carry over.
        let disk = if shape == "disk" { "_disk" } else { "" };
        let mut g = c.benchmark_group(format!("poisson_{n}x{n}{disk}_rgb_into_1024x1024"));
        g.sample_size(10)
            .throughput(Throughput::Elements(b.unknowns as u64));
        for threads in [1, 2] {
            let p = pool(threads);
            g.bench_with_input(
                BenchmarkId::from_parameter(format!("{threads}_threads")),
                &threads,
                |bch, _| bch.iter(|| p.install(|| black_box(seamless(&input, &params).unwrap()))),
            );
        }
        g.finish();
    }
}

fn field(c: &mut Criterion) {
    let n = 128usize;
    let m = (n as f64 - 1.0) / 2.0;
    let region: Vec<bool> = (0..n * n)
        .map(|i| {
            ((i / n) as f64 - m).powi(2) + ((i % n) as f64 - m).powi(2) < (0.48 * n as f64).powi(2)
        })
        .collect();
    // Displacements at points along a diagonal stroke, as the skeleton fit of §5.3 gives them.
    let points: Vec<[i64; 2]> = (0..12).map(|k| [24 + 7 * k, 26 + 6 * k]).collect();
    let values: Vec<f64> = (0..24)
        .map(|k| ((k * 37 % 11) as f64 - 5.0) * 0.3)
        .collect();
    let params = FieldParams::default();
    let f = interpolate_field(&region, n, n, &points, &values, 2, &params).unwrap();
    println!(
        "field {n}x{n} disk: {} iterations, residual {:.2e}",
        f.iterations, f.residual
    );
    let mut g = c.benchmark_group(format!("field_{n}x{n}_disk_2d"));
    g.sample_size(10).throughput(Throughput::Elements(
        region.iter().filter(|&&r| r).count() as u64
    ));
    g.bench_function("tol_1e-10", |b| {
        b.iter(|| {
            black_box(interpolate_field(&region, n, n, &points, &values, 2, &params).unwrap())
        });
    });
    g.finish();
}

fn deform(c: &mut Criterion) {
    let r = 67.0f64;
    let n = 2 * r as usize + 1;
    let disk: Vec<bool> = (0..n * n)
        .map(|i| ((i / n) as f64 - r).powi(2) + ((i % n) as f64 - r).powi(2) <= r * r)
        .collect();
    // A bent skeleton across the fragment, pulled onto a straight one by up to 4 px.
    let (cx, cy) = (500.0 + r, 300.0 + r);
    let points: Vec<[f64; 2]> = (0..60)
        .map(|k| {
            let t = (k as f64 / 59.0 - 0.5) * 1.8 * r;
            [cx + t, cy + 6.0 * (t / 20.0).sin()]
        })
        .collect();
    let displacement: Vec<[f64; 2]> = points.iter().map(|p| [0.0, -0.6 * (p[1] - cy)]).collect();
    let (c0, s0) = (0.4f64.cos(), 0.4f64.sin());
    let placement = Placement {
        shape: (n, n),
        origin: (300, 500),
        centre: [cx, cy],
        points: &points,
        displacement: &displacement,
        radius: r,
        rigid: [[c0, -s0], [s0, c0]],
        source_centre: [120.0, 140.0],
        disk: &disk,
    };
    let mut g = c.benchmark_group(format!("fragment_maps_{n}x{n}"));
    g.sample_size(20)
        .throughput(Throughput::Elements((n * n) as u64));
    g.bench_function("radius_67", |b| {
        b.iter(|| black_box(fragment_maps(&placement).unwrap()));
    });
    g.finish();
}

criterion_group!(benches, poisson, field, deform);
criterion_main!(benches);
