//! Criterion benches of the patch engine: PatchMatch (the 512×512, 7×7 RGB,
//! 5-iteration workload on 1 and 2 threads), exact search, k-NN and voting.
//!
//! `cargo bench -p phloem-core --bench patch`. Throughput is in target pixels per second;
//! candidate evaluations per second are printed once per workload.

mod common;

use std::hint::black_box;
use std::time::Instant;

use common::{load, pool};
use criterion::{criterion_group, criterion_main, BenchmarkId, Criterion, Throughput};
use phloem_core::image::Image;
use phloem_core::knn::{knn, KnnParams};
use phloem_core::patch::{nnf, Method, NnfInput, NnfParams};
use phloem_core::vote::vote;

fn input<'a>(src: &'a [f32], tgt: &'a [f32], n: usize) -> NnfInput<'a> {
    NnfInput::new(
        Image::new("source", src, n, n, 3).unwrap(),
        Image::new("target", tgt, n, n, 3).unwrap(),
    )
}

fn patchmatch(c: &mut Criterion) {
    let n = 512;
    let src = load("python/phloem/data/bark_douglas_fir.png", n as u32);
    let tgt = load("tests/data/water.jpg", n as u32);
    let params = NnfParams {
        patch_size: 7,
        iterations: 5,
        ..NnfParams::default()
    };
    let mut g = c.benchmark_group("patchmatch_512x512_7x7_rgb_5it");
    g.sample_size(10)
        .throughput(Throughput::Elements((n * n) as u64));
    for threads in [1, 2] {
        let p = pool(threads);
        let t0 = Instant::now();
        let evals = p.install(|| nnf(&input(&src, &tgt, n), &params).unwrap().evaluations);
        let dt = t0.elapsed().as_secs_f64();
        // Each evaluation is up to 7·7·3 = 147 multiply-adds (fewer with early termination).
        println!(
            "patchmatch {threads} thread(s): {evals} candidate evaluations, {:.1} M evaluations/s, {:.2} G multiply-adds/s upper bound",
            evals as f64 / dt / 1e6,
            evals as f64 * 147.0 / dt / 1e9
        );
        g.bench_with_input(
            BenchmarkId::from_parameter(format!("{threads}_threads")),
            &threads,
            |b, _| {
                b.iter(|| p.install(|| black_box(nnf(&input(&src, &tgt, n), &params).unwrap())));
            },
        );
    }
    g.finish();
}

fn exact(c: &mut Criterion) {
    let n = 64;
    let src = load("python/phloem/data/bark_douglas_fir.png", n as u32);
    let tgt = load("tests/data/water.jpg", n as u32);
    let params = NnfParams {
        method: Method::Exact,
        ..NnfParams::default()
    };
    let mut g = c.benchmark_group("exact_64x64_7x7_rgb");
    g.sample_size(10)
        .throughput(Throughput::Elements((n * n * (n - 6) * (n - 6)) as u64));
    g.bench_function("candidates", |b| {
        b.iter(|| black_box(nnf(&input(&src, &tgt, n), &params).unwrap()));
    });
    g.finish();
}

fn knn_bench(c: &mut Criterion) {
    let n = 128;
    let src = load("python/phloem/data/bark_douglas_fir.png", n as u32);
    let img = Image::new("exemplar", &src, n, n, 3).unwrap();
    let mut g = c.benchmark_group("knn_128x128_7x7_rgb_k4");
    g.sample_size(10)
        .throughput(Throughput::Elements((n * n) as u64));
    g.bench_function("approximate_6it", |b| {
        b.iter(|| black_box(knn(&img, None, &KnnParams::default()).unwrap()));
    });
    g.finish();
}

fn vote_bench(c: &mut Criterion) {
    let n = 512;
    let src = load("python/phloem/data/bark_douglas_fir.png", n as u32);
    let tgt = load("tests/data/water.jpg", n as u32);
    let f = nnf(
        &input(&src, &tgt, n),
        &NnfParams {
            iterations: 1,
            ..NnfParams::default()
        },
    )
    .unwrap();
    let img = Image::new("source", &src, n, n, 3).unwrap();
    let mut g = c.benchmark_group("vote_512x512_7x7_rgb");
    g.sample_size(10)
        .throughput(Throughput::Elements((n * n) as u64));
    g.bench_function("uniform", |b| {
        b.iter(|| black_box(vote(&img, &f.idx, n, n, None, 7).unwrap()));
    });
    g.finish();
}

criterion_group!(benches, patchmatch, exact, knn_bench, vote_bench);
criterion_main!(benches);
