//! The kd-tree seeded start of [`super::Method::KdTree`] (propagation-assisted kd-tree search,
//! He & Sun 2012): source patches projected onto a PCA basis, a kd-tree over them, and a
//! best-bin-first search for every target patch.

use std::collections::BinaryHeap;

use rayon::prelude::*;

use crate::kdtree::{KdTree, Pca};

use super::level::{unpack, Cell, Level};
use super::{KD_BUDGET, KD_CANDIDATES, KD_DIMS, KD_PCA_SAMPLES, NONE};

impl Level<'_> {
    /// The `p × p × c` values of the source patch centred at `s` (wholly inside the source).
    #[inline]
    fn source_patch(&self, s: u32, out: &mut [f32]) {
        let (sy, sx) = unpack(s);
        let (r, c) = (self.r, self.c);
        let len = (2 * r + 1) * c;
        for (k, o) in out.chunks_exact_mut(len).enumerate() {
            let s0 = ((sy - r + k) * self.sw + sx - r) * c;
            o.copy_from_slice(&self.src[s0..s0 + len]);
        }
    }

    /// Replaces every cell's match by the best of it and [`KD_CANDIDATES`] source patches
    /// found near the target patch in a PCA space of the source patches (see
    /// [`Method::KdTree`]); returns the candidates evaluated. Target patches clipped by the
    /// border take the PCA mean where they have no pixels, which projects to zero there.
    pub(super) fn kd_seed(&self, cells: &mut [Cell]) -> u64 {
        const CHUNK: usize = 256;
        let (r, c) = (self.r, self.c);
        let p = 2 * r + 1;
        let dim = p * p * c;
        let n = self.allowed_list.len();
        let step = n.div_ceil(KD_PCA_SAMPLES).max(1);
        let pca = Pca::fit(n.div_ceil(step), dim, KD_DIMS, |i, out| {
            self.source_patch(self.allowed_list[i * step], out);
        });
        let d = pca.d;
        let mut points = vec![0f32; n * d];
        points
            .par_chunks_mut(CHUNK * d)
            .enumerate()
            .for_each(|(ci, chunk)| {
                let mut v = vec![0f32; dim];
                for (j, o) in chunk.chunks_exact_mut(d).enumerate() {
                    self.source_patch(self.allowed_list[ci * CHUNK + j], &mut v);
                    pca.project(&v, o);
                }
            });
        let tree = KdTree::build(&points, d);
        let tw = self.tw;
        cells
            .par_chunks_mut(tw)
            .enumerate()
            .map(|(y, row)| {
                let mut v = vec![0f32; dim];
                let mut q = vec![0f32; d];
                let (mut found, mut heap) = (Vec::new(), BinaryHeap::new());
                let mut count = 0u64;
                for (x, cell) in row.iter_mut().enumerate() {
                    if cell.idx == NONE {
                        continue;
                    }
                    for (k, o) in v.chunks_exact_mut(p * c).enumerate() {
                        let ty = (y + k) as i64 - r as i64;
                        for (j, px) in o.chunks_exact_mut(c).enumerate() {
                            let tx = (x + j) as i64 - r as i64;
                            if let Some(t) = self.target_pixel(ty, tx) {
                                px.copy_from_slice(t);
                            } else {
                                let m0 = (k * p + j) * c;
                                px.copy_from_slice(&pca.mean[m0..m0 + c]);
                            }
                        }
                    }
                    pca.project(&v, &mut q);
                    tree.search(&q, KD_CANDIDATES, KD_BUDGET, &mut found, &mut heap);
                    for &(_, id) in &found {
                        let s = self.allowed_list[id as usize];
                        if s != cell.idx {
                            count += 1;
                            let dist = self.dist(y, x, s, cell.d);
                            if dist < cell.d {
                                *cell = Cell { idx: s, d: dist };
                            }
                        }
                    }
                }
                count
            })
            .sum()
    }
}
