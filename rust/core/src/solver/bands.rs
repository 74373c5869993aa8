//! Loops over fixed bands of grid rows: the parallel unit of every solver pass.
//!
//! A band is [`BAND`] rows whatever the thread count, and reductions sum per-band partial sums
//! in band order, so every result is the same bit for bit on any number of threads.

// Lane loops index several arrays in lockstep; the index form is what vectorises.
#![allow(clippy::needless_range_loop)]

use rayon::prelude::*;

/// Rows per parallel work item. Fixed (not derived from the thread count) so that every
/// reduction sums the same partial sums in the same order for any number of threads.
pub(crate) const BAND: usize = 8;

/// Grids with fewer cells than this are processed on the calling thread (same result).
/// Low enough that level 1 of a 256² region (131² cells) runs in parallel.
pub(crate) const PARALLEL_CELLS: usize = 12 * 1024;

/// Calls `f(row, out_row)` for every row of `out`, in parallel on large grids.
pub(crate) fn rows_mut<T: Send>(
    out: &mut [T],
    w: usize,
    f: impl Fn(usize, &mut [T]) + Sync + Send,
) {
    if out.len() >= PARALLEL_CELLS {
        out.par_chunks_mut(w).enumerate().for_each(|(y, r)| f(y, r));
    } else {
        out.chunks_mut(w).enumerate().for_each(|(y, r)| f(y, r));
    }
}

/// Calls `f(band_index, band)` on bands of [`BAND`] rows of `x` (rows `w` long; parallel on
/// large grids) and returns the results in band order.
pub(crate) fn bands<T: Send, R: Send>(
    x: &mut [T],
    w: usize,
    f: impl Fn(usize, &mut [T]) -> R + Sync,
) -> Vec<R> {
    if x.len() >= PARALLEL_CELLS {
        x.par_chunks_mut(BAND * w)
            .enumerate()
            .map(|(i, b)| f(i, b))
            .collect()
    } else {
        x.chunks_mut(BAND * w)
            .enumerate()
            .map(|(i, b)| f(i, b))
            .collect()
    }
}

/// The lane-wise sum of per-band partial sums, in band order.
pub(crate) fn sum_lanes<const L: usize>(parts: &[[f64; L]]) -> [f64; L] {
    let mut s = [0f64; L];
    for p in parts {
        for c in 0..L {
            s[c] += p[c];
        }
    }
    s
}

/// `⟨u, v⟩` per lane in `f64`, summed per band of [`BAND`] rows `w` long and then in band
/// order.
pub(crate) fn dot<T: Copy + Into<f64>, const L: usize>(
    u: &[[T; L]],
    v: &[[T; L]],
    w: usize,
) -> [f64; L] {
    let mut s = [0f64; L];
    for (a, b) in u.chunks(BAND * w).zip(v.chunks(BAND * w)) {
        let mut t = [0f64; L];
        for (x, y) in a.iter().zip(b) {
            for c in 0..L {
                let (x, y): (f64, f64) = (x[c].into(), y[c].into());
                t[c] += x * y;
            }
        }
        for c in 0..L {
            s[c] += t[c];
        }
    }
    s
}
