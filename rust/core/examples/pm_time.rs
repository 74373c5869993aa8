//! Times the PatchMatch workload (512×512 against 512×512, 7×7 RGB, 5 iterations)
//! and prints a checksum of the field, for A/B runs of kernel changes:
//! `cargo run --release -p phloem-core --example pm_time -- [threads] [repeats]`.

use std::path::Path;
use std::time::Instant;

use image::imageops::FilterType;
use phloem_core::image::Image;
use phloem_core::patch::{nnf, NnfInput, NnfParams};

fn load(rel: &str, size: u32) -> Vec<f32> {
    let root = Path::new(env!("CARGO_MANIFEST_DIR")).join("../..");
    let img = image::open(root.join(rel)).expect("image").to_rgb8();
    let img = image::imageops::resize(&img, size, size, FilterType::CatmullRom);
    img.into_raw()
        .into_iter()
        .map(|v| f32::from(v) / 255.0)
        .collect()
}

fn main() {
    let mut args = std::env::args().skip(1);
    let threads: usize = args.next().map_or(1, |s| s.parse().expect("threads"));
    let repeats: usize = args.next().map_or(3, |s| s.parse().expect("repeats"));
    let n = 512;
    // PM_SRC=128 shrinks the source (cache-resident) to separate memory from compute.
    let sn: usize = std::env::var("PM_SRC").map_or(n, |s| s.parse().expect("PM_SRC"));
    let src = load("python/phloem/data/bark_douglas_fir.png", sn as u32);
    // PM_TGT=bark matches the source against a shifted copy of itself (coherent case).
    let tgt = if std::env::var("PM_TGT").is_ok_and(|v| v == "bark") {
        let mut t = load("python/phloem/data/bark_douglas_fir.png", n as u32 + 8);
        let w = n + 8;
        let mut out = Vec::with_capacity(n * n * 3);
        for y in 0..n {
            out.extend_from_slice(&t[((y + 5) * w + 3) * 3..((y + 5) * w + 3 + n) * 3]);
        }
        t.clear();
        out
    } else {
        load("tests/data/water.jpg", n as u32)
    };
    let input = NnfInput::new(
        Image::new("source", &src, sn, sn, 3).unwrap(),
        Image::new("target", &tgt, n, n, 3).unwrap(),
    );
    // PM_IT=0 times the set-up alone (validation, level, initial field).
    let params = NnfParams {
        iterations: std::env::var("PM_IT").map_or(5, |s| s.parse().expect("PM_IT")),
        ..NnfParams::default()
    };

    let pool = rayon::ThreadPoolBuilder::new()
        .num_threads(threads)
        .build()
        .unwrap();
    let mut best = f64::INFINITY;
    let mut last = None;
    for _ in 0..repeats {
        let t0 = Instant::now();
        let f = pool.install(|| nnf(&input, &params).unwrap());
        best = best.min(t0.elapsed().as_secs_f64());
        last = Some(f);
    }
    let f = last.unwrap();
    let mut h: u64 = 0xcbf2_9ce4_8422_2325;
    for (i, d) in f.idx.iter().zip(&f.dist) {
        for v in [u64::from(*i), u64::from(d.to_bits())] {
            h = (h ^ v).wrapping_mul(0x100_0000_01b3);
        }
    }
    let mean = f.dist.iter().map(|&d| f64::from(d)).sum::<f64>() / f.dist.len() as f64;
    println!(
        "threads {threads}: best {best:.4} s, {} evals, {:.1} M evals/s, mean dist {mean:.6}, checksum {h:016x}",
        f.evaluations,
        f.evaluations as f64 / best / 1e6
    );
}
