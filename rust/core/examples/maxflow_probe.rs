use phloem_core::maxflow::{EdgeLayout, GridGraph};
fn read(p: &str) -> Vec<f32> {
    let b = std::fs::read(p).unwrap();
    b.chunks_exact(4)
        .map(|c| f32::from_le_bytes([c[0], c[1], c[2], c[3]]))
        .collect()
}
fn main() {
    let args: Vec<String> = std::env::args().collect();
    let (h, w): (usize, usize) = (args[1].parse().unwrap(), args[2].parse().unwrap());
    let n = format!("/tmp/prob_{h}x{w}");
    let e = read(&format!("{n}_edges.f32"));
    let s = read(&format!("{n}_source.f32"));
    let t = read(&format!("{n}_sink.f32"));
    let reps: usize = args.get(3).map_or(5, |v| v.parse().unwrap());
    for _ in 0..reps {
        let t0 = std::time::Instant::now();
        let mut g = GridGraph::new(h, w, 4).unwrap();
        g.set_edges("edges", &e, EdgeLayout::Symmetric).unwrap();
        g.set_terminals(&s, &t).unwrap();
        let f = g.maxflow();
        println!(
            "{h}x{w}: flow {f:.4} in {:.2} ms",
            t0.elapsed().as_secs_f64() * 1e3
        );
    }
}
