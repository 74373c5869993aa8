//! Exact search: the brute-force reference PatchMatch is measured against.

use rayon::prelude::*;

use super::level::{Cell, Level, EMPTY};
use super::NONE;

impl Level<'_> {
    /// Exact search: every allowed source centre for every target pixel that needs one.
    pub(super) fn exact(&self) -> (Vec<Cell>, u64) {
        let mut cells = vec![EMPTY; self.th * self.tw];
        cells
            .par_chunks_mut(self.tw)
            .enumerate()
            .for_each(|(y, row)| {
                for (x, cell) in row.iter_mut().enumerate() {
                    if !self.needs(y * self.tw + x) {
                        continue;
                    }
                    let mut best = Cell {
                        idx: NONE,
                        d: f32::INFINITY,
                    };
                    for &s in &self.allowed_list {
                        let d = self.dist(y, x, s, best.d);
                        if d < best.d {
                            best = Cell { idx: s, d };
                        }
                    }
                    *cell = best;
                }
            });
        let n = self.allowed_list.len() as u64 * self.need_count() as u64;
        (cells, n)
    }
}
