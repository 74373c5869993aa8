//! Criterion bench of a growth step's Rust work (Sibbing et al. 2010, §4.4), at the traced
//! retina's sizes (`benches/python/bench_branching_structure.py`): the density stamp of one
//! step (4 segments, ρ = 17 px, thickness 5 px, on a 1411² map) and the choice among 3952
//! candidate extensions of 4 points (700 rays of 12 samples, 4000 segments so far).
//!
//! `cargo bench -p phloem-core --bench growth`. Throughput: stamped segments, or candidates.

use std::hint::black_box;

use criterion::{criterion_group, criterion_main, Criterion, Throughput};
use phloem_core::colonisation::{stamp, DensityMap, DensityView, Rays};
use phloem_core::growth::{choose, Candidates, Colonisation, Step, Tip};

const SIDE: usize = 1411;

fn growth(c: &mut Criterion) {
    let mut density = vec![0.0f32; SIDE * SIDE];
    let mut owner_branch = vec![-1i32; SIDE * SIDE];
    let mut owner_vertex = vec![-1i32; SIDE * SIDE];
    // a wavy structure of 1000 stamps, so that the maps hold the density of a grown structure
    let mut segments = Vec::new();
    let step_points = |k: usize| -> Vec<[f64; 2]> {
        (0..5)
            .map(|i| {
                let s = (4 * k + i) as f64 * 4.2;
                let row = (s / 1300.0).floor();
                [
                    50.0 + s % 1300.0,
                    60.0 + 90.0 * row + 20.0 * (s / 40.0).sin(),
                ]
            })
            .collect()
    };
    {
        let mut map = DensityMap {
            density: &mut density,
            owner_branch: &mut owner_branch,
            owner_vertex: &mut owner_vertex,
            height: SIDE,
            width: SIDE,
        };
        for k in 0..1000 {
            let pts = step_points(k);
            stamp(&mut map, &pts, &[5.0; 5], 0, 4 * k as i32, 17.0).unwrap();
            for w in pts.windows(2) {
                segments.extend([w[0][0], w[0][1], w[1][0], w[1][1]]);
            }
        }
    }
    let mut group = c.benchmark_group("growth");
    group.throughput(Throughput::Elements(4));
    let pts = step_points(500);
    group.bench_function("stamp_4_segments", |b| {
        let (mut d, mut ob, mut ov) = (density.clone(), owner_branch.clone(), owner_vertex.clone());
        b.iter(|| {
            let mut map = DensityMap {
                density: &mut d,
                owner_branch: &mut ob,
                owner_vertex: &mut ov,
                height: SIDE,
                width: SIDE,
            };
            stamp(&mut map, black_box(&pts), &[5.0; 5], 1, 0, 17.0).unwrap()
        });
    });

    let (cands, m, n_rays) = (3952, 4, 700);
    let relative: Vec<f64> = (0..cands)
        .flat_map(|i| {
            let a = (i as f64 / cands as f64 - 0.5) * 3.0;
            (1..=m).flat_map(move |k| {
                let r = 4.2 * k as f64;
                [r * a.cos(), -r * a.sin()]
            })
        })
        .collect();
    let ray_of: Vec<usize> = (0..cands).map(|i| i * n_rays / cands).collect();
    let dirs: Vec<[f64; 2]> = (0..n_rays)
        .map(|k| {
            let a = (k as f64 / n_rays as f64 - 0.5) * 3.0;
            [a.cos(), -a.sin()]
        })
        .collect();
    let quality: Vec<f64> = (0..cands)
        .map(|i| ((i * 7919) % 1000) as f64 / 100.0)
        .collect();
    let tip = [700.0, 700.0];
    let view = DensityView {
        density: &density,
        owner_branch: &owner_branch,
        owner_vertex: &owner_vertex,
        height: SIDE,
        width: SIDE,
    };
    let step = Step {
        candidates: Candidates {
            relative: &relative,
            m,
            ray_of: &ray_of,
        },
        tip: Tip {
            point: tip,
            cos: 1.0,
            sin: 0.0,
        },
        shape: (SIDE, SIDE),
        rays: Rays {
            tip,
            directions: &dirs,
            length: 50.8,
            samples: 12,
        },
        colonisation: Some(Colonisation {
            view,
            skip: None,
            border_rho: None,
        }),
        guide: None,
        segments: &segments,
        eps: 1e-3,
    };
    assert_eq!(choose(&step, &quality, 2).unwrap().0.len(), 2);
    group.throughput(Throughput::Elements(cands as u64));
    group.bench_function("choose_2_of_3952", |b| {
        b.iter(|| choose(black_box(&step), black_box(&quality), 2).unwrap());
    });
    group.finish();
}

criterion_group!(benches, growth);
criterion_main!(benches);
