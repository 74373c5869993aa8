//! Criterion bench of texture-by-numbers on the thesis' bark1 inputs (263×324 exemplar
//! `ai.png`, 256×320 output from `b.png`), on 1 and 2 threads; the embedded bark with a
//! threshold label map stands in when `../shared` is absent.
//!
//! `cargo bench -p phloem-core --bench tbn`. Throughput is in output pixels per second. The
//! exemplar carries no feature map here (the Python API adds one), so this measures the
//! solver alone.

mod common;

use std::hint::black_box;

use common::{pool, root};
use criterion::{criterion_group, criterion_main, BenchmarkId, Criterion, Throughput};
use phloem_core::image::Image;
use phloem_core::tbn::{by_numbers, TbnInput, TbnParams};

struct Scene {
    ex: Vec<f32>,
    eh: usize,
    ew: usize,
    la: Vec<u32>,
    lb: Vec<u32>,
    oh: usize,
    ow: usize,
    name: &'static str,
}

fn rgb(path: &std::path::Path) -> (Vec<f32>, usize, usize) {
    let img = image::open(path).expect("bench image").to_rgb8();
    let (w, h) = img.dimensions();
    let v = img
        .into_raw()
        .into_iter()
        .map(|v| f32::from(v) / 255.0)
        .collect();
    (v, h as usize, w as usize)
}

/// Gray levels to compact labels, shared between the two maps (sorted gray values).
fn compact(maps: &[Vec<u8>]) -> Vec<Vec<u32>> {
    let mut values: Vec<u8> = maps.iter().flatten().copied().collect();
    values.sort_unstable();
    values.dedup();
    maps.iter()
        .map(|m| {
            m.iter()
                .map(|v| values.binary_search(v).unwrap() as u32)
                .collect()
        })
        .collect()
}

fn scene() -> Scene {
    let dir = root().join("../shared/data/bark/thesis_runs/bark1");
    if dir.join("ai.png").exists() {
        let (ex, eh, ew) = rgb(&dir.join("ai.png"));
        let gray = |f: &str| {
            let g = image::open(dir.join(f)).expect("label map").to_luma8();
            (g.width() as usize, g.height() as usize, g.into_raw())
        };
        let (_, _, a) = gray("a.png");
        let (ow, oh, b) = gray("b.png");
        let l = compact(&[a, b]);
        return Scene {
            ex,
            eh,
            ew,
            la: l[0].clone(),
            lb: l[1].clone(),
            oh,
            ow,
            name: "bark1_263x324_to_256x320",
        };
    }
    let (ex, eh, ew) = rgb(&root().join("python/phloem/data/bark_douglas_fir.png"));
    let la: Vec<u32> = ex
        .chunks_exact(3)
        .map(|p| u32::from(p.iter().sum::<f32>() > 0.9))
        .collect();
    // Output labels: the exemplar's map mirrored left to right.
    let lb: Vec<u32> = (0..eh * ew)
        .map(|i| la[(i / ew) * ew + ew - 1 - i % ew])
        .collect();
    Scene {
        ex,
        eh,
        ew,
        la,
        lb,
        oh: eh,
        ow: ew,
        name: "embedded_bark_256x256",
    }
}

fn tbn(c: &mut Criterion) {
    let s = scene();
    let input = TbnInput {
        exemplar: Image::new("exemplar", &s.ex, s.eh, s.ew, 3).unwrap(),
        weights: None,
        labels_in: &s.la,
        labels_out: &s.lb,
        out_h: s.oh,
        out_w: s.ow,
    };
    let params = TbnParams::default();
    let mut g = c.benchmark_group(format!("tbn_{}", s.name));
    g.sample_size(10)
        .throughput(Throughput::Elements((s.oh * s.ow) as u64));
    for threads in [1, 2] {
        let p = pool(threads);
        g.bench_with_input(
            BenchmarkId::from_parameter(format!("{threads}_threads")),
            &threads,
            |b, _| {
                b.iter(|| p.install(|| black_box(by_numbers(&input, &params, None).unwrap())));
            },
        );
    }
    g.finish();
}

criterion_group!(benches, tbn);
criterion_main!(benches);
