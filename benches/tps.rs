//! TPS-RPM registration of 100 keypoints and the dense fields of a 2 Mpx image.
//! `cargo bench -p phloem-core --bench tps`.

use criterion::{criterion_group, criterion_main, Criterion};
use phloem_core::tps::{self, Params, Point, Side};

fn leaf(n: usize) -> Vec<Point> {
    let rib = n / 5;
    let outline = n - rib;
    let mut p: Vec<Point> = (0..outline)
        .map(|k| {
            let a = std::f64::consts::TAU * k as f64 / outline as f64;
            [
                800.0 + 600.0 * a.cos(),
                600.0 + 320.0 * (1.0 - 0.35 * a.cos()) * a.sin(),
            ]
        })
        .collect();
    p.extend((0..rib).map(|k| [280.0 + 1040.0 * (k as f64 + 0.5) / rib as f64, 600.0]));
    p
}

fn warp(p: Point) -> Point {
    let (x, y) = (p[0] - 800.0, p[1] - 600.0);
    [
        820.0 + 1.05 * x + 30.0 * (y / 200.0).sin(),
        590.0 + 0.95 * y + 60.0 * (x / 600.0).powi(2),
    ]
}

fn bench(c: &mut Criterion) {
    let x = leaf(100);
    let y: Vec<Point> = x.iter().map(|&p| warp(p)).collect();
    let p = Params::default();
    c.bench_function("tps_rpm_100_points", |b| {
        b.iter(|| tps::rpm(&x, &y, &p, ("x", "y")).unwrap());
    });
    let side = Side {
        size: (1200, 1700),
        mask: None,
    };
    let r = tps::rpm(&x, &y, &p, ("x", "y")).unwrap();
    let mut g = c.benchmark_group("dense");
    g.sample_size(10);
    g.bench_function("forward_field_2mpx", |b| {
        b.iter(|| tps::dense::field(1200, 1700, 4, |q| r.tps.eval(q)).unwrap());
    });
    g.bench_function("register_dense_2mpx_both_fields", |b| {
        b.iter(|| tps::register(&x, &y, &p, side, side, 4).unwrap());
    });
    g.finish();
}

criterion_group!(benches, bench);
criterion_main!(benches);
