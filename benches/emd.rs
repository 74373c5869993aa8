//! Criterion benches of the colour term of layer induction (Assa & Cohen-Or, Eq. 1): the
//! normalised EMD map of a 1024² label map over a 16-colour palette against one target
//! histogram, 8 × 8 windows, on 1 and 2 threads. Two label maps: the embedded bark photo
//! quantised to 16 grey levels (a real texture: neighbouring windows often share a basis) and
//! uniformly random labels (the worst case: every window differs and holds ~all 16 colours).
//!
//! `cargo bench -p phloem-core --bench emd`. Throughput is in pixels per second.

mod common;

use std::hint::black_box;

use common::{load, pool};
use criterion::{criterion_group, criterion_main, BenchmarkId, Criterion, Throughput};
use phloem_core::emd::{emd_map, MapInput};

const N: usize = 1024;
const BINS: usize = 16;

/// Palette colours on a helix through CIELAB, as a k-means palette of a leaf roughly is.
fn ground() -> Vec<f64> {
    let p: Vec<[f64; 3]> = (0..BINS)
        .map(|i| {
            let t = i as f64;
            [
                20.0 + 4.0 * t,
                25.0 * (0.7 * t).cos(),
                25.0 * (0.7 * t).sin(),
            ]
        })
        .collect();
    (0..BINS * BINS)
        .map(|c| {
            let (a, b) = (p[c / BINS], p[c % BINS]);
            ((a[0] - b[0]).powi(2) + (a[1] - b[1]).powi(2) + (a[2] - b[2]).powi(2)).sqrt()
        })
        .collect()
}

fn emd(c: &mut Criterion) {
    let rgb = load("python/phloem/data/bark_douglas_fir.png", N as u32);
    let photo: Vec<i32> = rgb
        .chunks_exact(3)
        .map(|p| (((p[0] + p[1] + p[2]) / 3.0 * BINS as f32) as i32).clamp(0, BINS as i32 - 1))
        .collect();
    let mut z = 0x9e37_79b9_7f4a_7c15u64;
    let random: Vec<i32> = (0..N * N)
        .map(|_| {
            z ^= z << 13;
            z ^= z >> 7;
            z ^= z << 17;
            (z % BINS as u64) as i32
        })
        .collect();
    let g = ground();
    let target: Vec<f64> = (0..BINS)
        .map(|i| if i % 3 == 0 { 1.0 + i as f64 } else { 0.0 })
        .collect();
    let mut group = c.benchmark_group("emd_map_1024x1024_16bins_8x8");
    group
        .sample_size(10)
        .throughput(Throughput::Elements((N * N) as u64));
    for (name, labels) in [("bark_photo", &photo), ("random_labels", &random)] {
        let input = MapInput {
            labels,
            size: (N, N),
            n_bins: BINS,
            ground: &g,
            target: &target,
            window: 8,
        };
        for threads in [1, 2] {
            let p = pool(threads);
            group.bench_with_input(
                BenchmarkId::new(name, format!("{threads}_threads")),
                &threads,
                |b, _| b.iter(|| p.install(|| black_box(emd_map(&input).unwrap()))),
            );
        }
    }
    group.finish();
}

criterion_group!(benches, emd);
criterion_main!(benches);
