//! Criterion benches of the graph-cut engine: max-flow on the seam workloads (real
//! overlaps of H×W pixels, Kwatra capacities, the first column tied to the source and the last
//! to the sink) and the end-to-end seam finder, on 1 and 2 threads.
//!
//! `cargo bench -p phloem-core --bench seams`. Throughput is in pixels per second. The same
//! workloads against PyMaxflow: `python benches/bench_seams.py`.

mod common;

use std::hint::black_box;

use common::pool;
use criterion::{criterion_group, criterion_main, BenchmarkId, Criterion, Throughput};
use phloem_core::image::Image;
use phloem_core::maxflow::{EdgeLayout, GridGraph};
use phloem_core::seams::{seam, SeamInput};

/// The embedded bark, mirror-tiled to `h × w`, starting at `(y0, x0)` of the tiling, as RGB
/// f32 in [0, 1] (the overlaps of `bench_seams.py`).
fn bark(h: usize, w: usize, y0: usize, x0: usize, flip: bool) -> Vec<f32> {
    let img = image::open(common::root().join("python/phloem/data/bark_douglas_fir.png"))
        .expect("bench image")
        .to_rgb8();
    let (bh, bw) = (img.height() as usize, img.width() as usize);
    let mirror = |v: usize, n: usize| {
        let v = v % (2 * n);
        if v < n {
            v
        } else {
            2 * n - 1 - v
        }
    };
    let mut out = Vec::with_capacity(h * w * 3);
    for y in 0..h {
        let yy = if flip { h - 1 - y } else { y };
        for x in 0..w {
            let p = img.get_pixel(mirror(x0 + x, bw) as u32, mirror(y0 + yy, bh) as u32);
            out.extend(p.0.iter().map(|&v| f32::from(v) / 255.0));
        }
    }
    out
}

struct Problem {
    h: usize,
    w: usize,
    a: Vec<f32>,
    b: Vec<f32>,
    edges: Vec<f32>,
    source: Vec<f32>,
    sink: Vec<f32>,
}

fn problem(h: usize, w: usize) -> Problem {
    let a = bark(h, w, 0, 0, false);
    let b = bark(h, w, 211, 97, true);
    let d: Vec<f32> = a
        .chunks_exact(3)
        .zip(b.chunks_exact(3))
        .map(|(p, q)| {
            p.iter()
                .zip(q)
                .map(|(u, v)| (u - v) * (u - v))
                .sum::<f32>()
                .sqrt()
        })
        .collect();
    let mut edges = vec![0f32; h * w * 2];
    for y in 0..h {
        for x in 0..w {
            let i = y * w + x;
            if x + 1 < w {
                edges[i * 2] = d[i] + d[i + 1];
            }
            if y + 1 < h {
                edges[i * 2 + 1] = d[i] + d[i + w];
            }
        }
    }
    let mut source = vec![0f32; h * w];
    let mut sink = vec![0f32; h * w];
    for y in 0..h {
        source[y * w] = f32::INFINITY;
        sink[y * w + w - 1] = f32::INFINITY;
    }
    Problem {
        h,
        w,
        a,
        b,
        edges,
        source,
        sink,
    }
}

fn maxflow(c: &mut Criterion) {
    let mut g = c.benchmark_group("maxflow");
    g.sample_size(10);
    for (h, w) in [(256, 32), (512, 64), (1024, 128)] {
        let p = problem(h, w);
        g.throughput(Throughput::Elements((h * w) as u64));
        for threads in [1, 2] {
            let pool = pool(threads);
            g.bench_with_input(
                BenchmarkId::new(format!("{h}x{w}"), threads),
                &p,
                |bch, p| {
                    bch.iter(|| {
                        pool.install(|| {
                            let mut gg = GridGraph::new(p.h, p.w, 4).unwrap();
                            gg.set_edges("edges", &p.edges, EdgeLayout::Symmetric)
                                .unwrap();
                            gg.set_terminals(&p.source, &p.sink).unwrap();
                            black_box(gg.maxflow())
                        })
                    });
                },
            );
        }
    }
    g.finish();
}

fn seam_end_to_end(c: &mut Criterion) {
    let mut g = c.benchmark_group("seam");
    g.sample_size(10);
    let (h, w) = (512, 64);
    let p = problem(h, w);
    let region = vec![true; h * w];
    let mut seeds = vec![0u8; h * w];
    for y in 0..h {
        seeds[y * w] = 1;
        seeds[y * w + w - 1] = 2;
    }
    g.throughput(Throughput::Elements((h * w) as u64));
    let pool = pool(2);
    g.bench_function("kwatra_512x64", |bch| {
        bch.iter(|| {
            pool.install(|| {
                let a = Image::new("a", &p.a, h, w, 3).unwrap();
                let b = Image::new("b", &p.b, h, w, 3).unwrap();
                let mut inp = SeamInput::new(a, b, &region);
                inp.seeds = Some(&seeds);
                black_box(seam(&inp).unwrap().energy)
            })
        });
    });
    g.finish();
}

criterion_group!(benches, maxflow, seam_end_to_end);
criterion_main!(benches);
