//! The pyramid of reference images of Laitoch 2018, §3.3.2: level sizes that double going up
//! (the finest step may grow by less than two), downsampling by removing rows and columns
//! (never two adjacent ones) and upsampling that adds back exactly those rows and columns,
//! each new pixel inheriting its top / left / top-left neighbour's reference shifted by one.

/// Sizes of one axis from the finest (index 0) to the coarsest (index `levels - 1`).
///
/// The coarsest size is `ceil(n / 2^(levels-1))` and every coarser size is exactly half the
/// next finer one, except that the finest level may be less than twice level 1.
#[must_use]
pub fn level_sizes(n: usize, levels: usize) -> Vec<usize> {
    let levels = levels.max(1);
    let coarsest = n.div_ceil(1 << (levels - 1)).max(1);
    let mut out: Vec<usize> = (0..levels).map(|l| coarsest << (levels - 1 - l)).collect();
    out[0] = n;
    out
}

/// Which indices of an axis of length `fine` survive downsampling to `coarse`
/// (`fine / 2 <= coarse <= fine`): the removed ones are `floor((i + ½) · fine / r)` for
/// `i < r = fine − coarse`, so they are spread uniformly and never adjacent. For
/// `fine = 2 · coarse` the odd indices go.
#[must_use]
pub fn kept(fine: usize, coarse: usize) -> Vec<usize> {
    debug_assert!(coarse <= fine && 2 * coarse >= fine);
    let r = fine - coarse;
    let mut removed = vec![false; fine];
    for i in 0..r {
        removed[((2 * i + 1) * fine) / (2 * r)] = true;
    }
    (0..fine).filter(|&i| !removed[i]).collect()
}

/// One downsampling step of a 2-D grid: kept rows and kept columns.
#[derive(Clone, Debug)]
pub struct Step {
    /// Kept fine rows, one per coarse row.
    pub rows: Vec<usize>,
    /// Kept fine columns, one per coarse column.
    pub cols: Vec<usize>,
    /// Fine height.
    pub fh: usize,
    /// Fine width.
    pub fw: usize,
}

impl Step {
    /// The step from `fh × fw` to `ch × cw`.
    #[must_use]
    pub fn new(fh: usize, fw: usize, ch: usize, cw: usize) -> Self {
        Self {
            rows: kept(fh, ch),
            cols: kept(fw, cw),
            fh,
            fw,
        }
    }

    /// Coarse height.
    #[must_use]
    pub fn ch(&self) -> usize {
        self.rows.len()
    }

    /// Coarse width.
    #[must_use]
    pub fn cw(&self) -> usize {
        self.cols.len()
    }

    /// Keeps the surviving pixels of a `fh × fw × c` buffer.
    #[must_use]
    pub fn down<T: Copy>(&self, data: &[T], c: usize) -> Vec<T> {
        let mut out = Vec::with_capacity(self.ch() * self.cw() * c);
        for &y in &self.rows {
            for &x in &self.cols {
                out.extend_from_slice(&data[(y * self.fw + x) * c..][..c]);
            }
        }
        out
    }

    /// For every fine index, the coarse index it inherits from and how far it lies past the
    /// kept index (0 for kept ones, 1 for re-added ones).
    fn parents(kept: &[usize], fine: usize) -> Vec<(usize, usize)> {
        let mut out = Vec::with_capacity(fine);
        let mut j = 0;
        for i in 0..fine {
            while j + 1 < kept.len() && kept[j + 1] <= i {
                j += 1;
            }
            out.push((j, i - kept[j]));
        }
        out
    }
}

/// Maps references (flat exemplar indices) of a coarse exemplar to the fine one.
pub(crate) fn ref_up(e: u32, ex: &Step) -> (i64, i64) {
    let (ey, exx) = (e as usize / ex.cw(), e as usize % ex.cw());
    (ex.rows[ey] as i64, ex.cols[exx] as i64)
}

/// Upsamples an output image of references (§3.3.2, Fig. 3.2): `refs` is `out.ch() ×
/// out.cw()` flat indices into the coarse exemplar of `ex`; the result is `out.fh × out.fw`
/// flat indices into the fine exemplar. Kept pixels take their coarse reference mapped to the
/// fine exemplar; a re-added pixel takes its top, left or top-left neighbour's reference
/// shifted by its offset, wrapped or clamped to the exemplar.
#[must_use]
pub fn upsample_refs(refs: &[u32], out: &Step, ex: &Step, wrap: bool) -> Vec<u32> {
    let py = Step::parents(&out.rows, out.fh);
    let px = Step::parents(&out.cols, out.fw);
    let (eh, ew) = (ex.fh as i64, ex.fw as i64);
    let mut fine = Vec::with_capacity(out.fh * out.fw);
    for &(cy, dy) in &py {
        for &(cx, dx) in &px {
            let (y, x) = ref_up(refs[cy * out.cw() + cx], ex);
            let (mut y, mut x) = (y + dy as i64, x + dx as i64);
            if wrap {
                y = y.rem_euclid(eh);
                x = x.rem_euclid(ew);
            } else {
                y = y.min(eh - 1);
                x = x.min(ew - 1);
            }
            fine.push((y * ew + x) as u32);
        }
    }
    fine
}

/// Downsamples an output image of references: keeps the surviving output pixels and maps
/// each reference to the coarse exemplar (a reference to a removed exemplar row or column
/// goes to the kept one before it). The inverse of [`upsample_refs`].
#[must_use]
pub fn downsample_refs(refs: &[u32], out: &Step, ex: &Step) -> Vec<u32> {
    let py = Step::parents(&ex.rows, ex.fh);
    let px = Step::parents(&ex.cols, ex.fw);
    out.down(refs, 1)
        .into_iter()
        .map(|e| {
            let (y, x) = (e as usize / ex.fw, e as usize % ex.fw);
            (py[y].0 * ex.cw() + px[x].0) as u32
        })
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::rng::Rng;

    #[test]
    fn sizes_double_except_the_finest_step() {
        assert_eq!(level_sizes(263, 3), vec![263, 132, 66]);
        assert_eq!(level_sizes(256, 3), vec![256, 128, 64]);
        assert_eq!(level_sizes(100, 1), vec![100]);
        for n in 5..300 {
            for l in 1..5 {
                let s = level_sizes(n, l);
                for i in 1..s.len() {
                    assert!(s[i] <= s[i - 1] && 2 * s[i] >= s[i - 1], "{n} {l} {s:?}");
                    if i >= 2 {
                        assert_eq!(s[i - 1], 2 * s[i]);
                    }
                }
            }
        }
    }

    #[test]
    fn removed_indices_are_spread_and_never_adjacent() {
        assert_eq!(kept(8, 4), vec![0, 2, 4, 6]);
        for fine in 2usize..200 {
            for coarse in fine.div_ceil(2)..=fine {
                let k = kept(fine, coarse);
                assert_eq!(k.len(), coarse);
                assert_eq!(k[0], 0);
                // Between consecutive kept indices at most one was removed.
                assert!(
                    k.windows(2).all(|w| w[1] - w[0] <= 2),
                    "{fine} {coarse} {k:?}"
                );
                assert!(fine - 1 - k[coarse - 1] <= 1);
            }
        }
    }

    #[test]
    fn up_and_down_are_inverse() {
        for (oh, ow, eh, ew) in [
            (16usize, 20usize, 14usize, 18usize),
            (9, 7, 11, 13),
            (256, 320, 263, 324),
        ] {
            for wrap in [false, true] {
                let out = Step::new(oh, ow, oh.div_ceil(2), ow.div_ceil(2));
                let ex = Step::new(eh, ew, eh.div_ceil(2), ew.div_ceil(2));
                let mut rng = Rng::keyed(5, oh as u64, 0);
                let n = (ex.ch() * ex.cw()) as u64;
                let coarse: Vec<u32> = (0..out.ch() * out.cw())
                    .map(|_| rng.below(n) as u32)
                    .collect();
                let fine = upsample_refs(&coarse, &out, &ex, wrap);
                assert_eq!(fine.len(), oh * ow);
                assert_eq!(downsample_refs(&fine, &out, &ex), coarse);
                // A kept pixel resolves to the same exemplar pixel at both levels.
                let img: Vec<u32> = (0..(eh * ew) as u32).collect();
                let cimg = ex.down(&img, 1);
                let fres = out.down(
                    &fine.iter().map(|&e| img[e as usize]).collect::<Vec<_>>(),
                    1,
                );
                let cres: Vec<u32> = coarse.iter().map(|&e| cimg[e as usize]).collect();
                assert_eq!(fres, cres);
            }
        }
    }

    #[test]
    fn coherent_blocks_stay_coherent_when_upsampled() {
        // A coarse output that copies the coarse exemplar verbatim upsamples to a verbatim copy
        // of the fine exemplar.
        let (eh, ew) = (12, 10);
        let ex = Step::new(eh, ew, 6, 5);
        let out = Step::new(eh, ew, 6, 5);
        let coarse: Vec<u32> = (0..30).collect();
        let fine = upsample_refs(&coarse, &out, &ex, false);
        assert_eq!(fine, (0..(eh * ew) as u32).collect::<Vec<_>>());
    }
}
