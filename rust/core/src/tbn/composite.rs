//! Graph-cut compositing of a reference image (after Kwatra, Schödl, Essa, Turk, Bobick
//! 2003, "Graphcut textures"): grow coherent pieces of the exemplar by α-expansion moves.
//!
//! The reference image is seen as a field of offsets (exemplar pixel − output pixel). Over
//! windows of [`WINDOW`]² pixels (stride [`STRIDE`], a random phase per round), each of the
//! window's most frequent offsets α in turn may take over any of the window's pixels by a
//! minimum cut, under the seam cost of Kwatra et al. 2003 (Eq. 1): between neighbours `p`,
//! `q` with offsets `a`, `b`, `‖I(p+a) − I(p+b)‖ + ‖I(q+a) − I(q+b)‖`, zero where the two
//! offsets' copies agree and zero inside a piece. The cost is a metric in the offsets, so
//! every move is an exact α-expansion (Boykov, Veksler, Zabih 2001) and never raises the
//! energy. α may only take pixels whose copy lies inside the exemplar and has the output's
//! label, so every output pixel stays an exemplar pixel of its own label.
//!
//! Windows of one phase (every third window in each direction) share no pixel and no
//! neighbour pair, so they are solved in parallel and the result does not depend on the
//! number of threads.

use rayon::prelude::*;

use crate::error::Result;
use crate::maxflow::{EdgeLayout, GridGraph};
use crate::rng::Rng;

/// Side of a compositing window.
pub const WINDOW: usize = 32;
/// Distance between neighbouring windows.
pub const STRIDE: usize = 16;
/// Offsets tried per window: its most frequent ones. On the thesis' bark runs 3 per window
/// and 1 round came within 0.02 of 6 per window and 3 rounds in patch coherence.
pub const CANDIDATES: usize = 4;

/// The exemplar and the label maps the compositing works on.
pub struct Scene<'a> {
    /// Exemplar values, `eh × ew × stride`, of which the first `c` of each pixel are compared.
    pub ex: &'a [f32],
    /// Values per exemplar pixel in `ex`.
    pub stride: usize,
    /// Values compared per pixel.
    pub c: usize,
    /// Exemplar height and width.
    pub eh: usize,
    /// Exemplar width.
    pub ew: usize,
    /// Exemplar labels.
    pub labels_in: &'a [u32],
    /// Output labels, `h × w`.
    pub labels_out: &'a [u32],
    /// Output height.
    pub h: usize,
    /// Output width.
    pub w: usize,
}

impl Scene<'_> {
    /// The exemplar pixel output pixel `(y, x)` copies under offset `o`, clamped to the
    /// exemplar.
    #[inline]
    fn px(&self, y: usize, x: usize, o: (i32, i32)) -> &[f32] {
        let sy = (y as i64 + i64::from(o.0)).clamp(0, self.eh as i64 - 1) as usize;
        let sx = (x as i64 + i64::from(o.1)).clamp(0, self.ew as i64 - 1) as usize;
        let i = (sy * self.ew + sx) * self.stride;
        &self.ex[i..i + self.c]
    }

    /// Whether offset `o` may be used at output pixel `(y, x)`.
    #[inline]
    fn valid(&self, y: usize, x: usize, o: (i32, i32)) -> bool {
        let (sy, sx) = (y as i64 + i64::from(o.0), x as i64 + i64::from(o.1));
        sy >= 0
            && sx >= 0
            && (sy as usize) < self.eh
            && (sx as usize) < self.ew
            && self.labels_in[sy as usize * self.ew + sx as usize]
                == self.labels_out[y * self.w + x]
    }

    /// `‖I(y, x, a) − I(y, x, b)‖`.
    #[inline]
    fn diff(&self, y: usize, x: usize, a: (i32, i32), b: (i32, i32)) -> f32 {
        if a == b {
            return 0.0;
        }
        self.px(y, x, a)
            .iter()
            .zip(self.px(y, x, b))
            .map(|(u, v)| (u - v) * (u - v))
            .sum::<f32>()
            .sqrt()
    }
}

/// Composites `refs` (flat exemplar indices, every one valid for its pixel) in place:
/// `rounds` passes over the windows, trying each window's [`CANDIDATES`] most frequent
/// offsets.
///
/// # Errors
/// Only if the max-flow graph cannot be built (never for a window of checked size).
pub fn composite(scene: &Scene<'_>, refs: &mut [u32], rounds: usize, seed: u64) -> Result<()> {
    let (h, w, ew) = (scene.h, scene.w, scene.ew);
    let mut off: Vec<(i32, i32)> = refs
        .iter()
        .enumerate()
        .map(|(i, &e)| {
            let e = e as usize;
            (
                (e / ew) as i32 - (i / w) as i32,
                (e % ew) as i32 - (i % w) as i32,
            )
        })
        .collect();
    for round in 0..rounds {
        let mut rng = Rng::keyed(seed, 0xC0_4D05, round as u64);
        let oy = rng.below(STRIDE as u64) as i64;
        let ox = rng.below(STRIDE as u64) as i64;
        let ny = (h + oy as usize).div_ceil(STRIDE);
        let nx = (w + ox as usize).div_ceil(STRIDE);
        for phase in 0..9 {
            let (py, px) = (phase / 3, phase % 3);
            let wins: Vec<(usize, usize, usize, usize)> = (py..ny)
                .step_by(3)
                .flat_map(|iy| (px..nx).step_by(3).map(move |ix| (iy, ix)))
                .filter_map(|(iy, ix)| {
                    let y0 = iy as i64 * STRIDE as i64 - oy;
                    let x0 = ix as i64 * STRIDE as i64 - ox;
                    let (y1, x1) = (y0.max(0) as usize, x0.max(0) as usize);
                    let y2 = ((y0 + WINDOW as i64).max(0) as usize).min(h);
                    let x2 = ((x0 + WINDOW as i64).max(0) as usize).min(w);
                    (y2 >= y1 + 2 && x2 >= x1 + 2).then_some((y1, x1, y2, x2))
                })
                .collect();
            let changes: Vec<Vec<(usize, (i32, i32))>> = wins
                .par_iter()
                .map(|&win| window(scene, &off, win, CANDIDATES))
                .collect::<Result<_>>()?;
            for (i, o) in changes.into_iter().flatten() {
                off[i] = o;
            }
        }
    }
    for (i, (r, o)) in refs.iter_mut().zip(&off).enumerate() {
        let y = (i / w) as i64 + i64::from(o.0);
        let x = (i % w) as i64 + i64::from(o.1);
        *r = (y as usize * ew + x as usize) as u32;
    }
    Ok(())
}

/// α-expansions of one window `(y1, x1, y2, x2)`; returns the changed pixels.
fn window(
    scene: &Scene<'_>,
    off: &[(i32, i32)],
    (y1, x1, y2, x2): (usize, usize, usize, usize),
    candidates: usize,
) -> Result<Vec<(usize, (i32, i32))>> {
    let (h, w) = (scene.h, scene.w);
    let (wh, ww) = (y2 - y1, x2 - x1);
    // Local copy of the offsets of the window and its one-pixel ring.
    let (ey1, ex1) = (y1.saturating_sub(1), x1.saturating_sub(1));
    let (ey2, ex2) = ((y2 + 1).min(h), (x2 + 1).min(w));
    let lw = ex2 - ex1;
    let mut loc: Vec<(i32, i32)> = (ey1..ey2)
        .flat_map(|y| off[y * w + ex1..y * w + ex2].iter().copied())
        .collect();
    let at = |y: usize, x: usize| (y - ey1) * lw + (x - ex1);
    let inner = |y: usize, x: usize| y >= y1 && y < y2 && x >= x1 && x < x2;

    // The window's most frequent offsets, ties by offset.
    let mut counted: Vec<(i32, i32)> = (y1..y2)
        .flat_map(|y| off[y * w + x1..y * w + x2].iter().copied())
        .collect();
    counted.sort_unstable();
    let mut runs: Vec<(usize, (i32, i32))> = Vec::new();
    for o in counted {
        match runs.last_mut() {
            Some((n, last)) if *last == o => *n += 1,
            _ => runs.push((1, o)),
        }
    }
    runs.sort_by(|a, b| b.0.cmp(&a.0).then(a.1.cmp(&b.1)));
    runs.truncate(candidates);

    let mut graph = GridGraph::new(wh, ww, 4)?;
    let mut edges = vec![0f32; wh * ww * 4];
    let mut changed = false;
    let mut src = vec![0f32; wh * ww];
    let mut snk = vec![0f32; wh * ww];
    for &(_, alpha) in &runs {
        // Nothing to gain unless α may take a pixel it does not hold yet.
        let gain =
            (y1..y2).any(|y| (x1..x2).any(|x| loc[at(y, x)] != alpha && scene.valid(y, x, alpha)));
        if !gain {
            continue;
        }
        edges.fill(0.0);
        src.fill(0.0);
        snk.fill(0.0);
        let unary = |y: usize, x: usize, c: f32, src: &mut [f32], snk: &mut [f32]| {
            let k = (y - y1) * ww + (x - x1);
            if c > 0.0 {
                src[k] += c;
            } else {
                snk[k] -= c;
            }
        };
        for y in ey1..ey2 {
            for x in ex1..ex2 {
                let cp = loc[at(y, x)];
                let pin = inner(y, x);
                for (d, (dy, dx)) in [(0usize, (0usize, 1usize)), (1, (1, 0))] {
                    let (qy, qx) = (y + dy, x + dx);
                    if qy >= ey2 || qx >= ex2 {
                        continue;
                    }
                    let qin = inner(qy, qx);
                    if !pin && !qin {
                        continue;
                    }
                    let cq = loc[at(qy, qx)];
                    // E(x_p, x_q) for keep (0) / take α (1).
                    let e00 = scene.diff(y, x, cp, cq) + scene.diff(qy, qx, cp, cq);
                    let e01 = scene.diff(y, x, cp, alpha) + scene.diff(qy, qx, cp, alpha);
                    let e10 = scene.diff(y, x, alpha, cq) + scene.diff(qy, qx, alpha, cq);
                    if pin && qin {
                        unary(y, x, e10 - e00, &mut src, &mut snk);
                        unary(qy, qx, -e10, &mut src, &mut snk);
                        edges[((y - y1) * ww + (x - x1)) * 4 + d] = (e01 + e10 - e00).max(0.0);
                    } else if pin {
                        unary(y, x, e10 - e00, &mut src, &mut snk);
                    } else {
                        unary(qy, qx, e01 - e00, &mut src, &mut snk);
                    }
                }
            }
        }
        for y in y1..y2 {
            for x in x1..x2 {
                if !scene.valid(y, x, alpha) {
                    src[(y - y1) * ww + (x - x1)] = f32::INFINITY;
                    snk[(y - y1) * ww + (x - x1)] = 0.0;
                }
            }
        }
        graph.set_edges("edges", &edges, EdgeLayout::Directed)?;
        graph.set_terminals(&src, &snk)?;
        graph.maxflow();
        let side = graph.sink_side().expect("solved");
        for y in y1..y2 {
            for x in x1..x2 {
                if side[(y - y1) * ww + (x - x1)] && loc[at(y, x)] != alpha {
                    loc[at(y, x)] = alpha;
                    changed = true;
                }
            }
        }
    }
    let mut out = Vec::new();
    if changed {
        for y in y1..y2 {
            for x in x1..x2 {
                if loc[at(y, x)] != off[y * w + x] {
                    out.push((y * w + x, loc[at(y, x)]));
                }
            }
        }
    }
    Ok(out)
}
