//! Preconditioned conjugate gradients (Hestenes & Stiefel 1952; Saad, *Iterative Methods for
//! Sparse Linear Systems*, 2003, Alg. 9.1) for the symmetric positive definite systems of the
//! gradient-domain solvers, `L` right-hand sides (lanes) at once.
//!
//! The iterate and the final residual check are `f64`; the residual recurrence, the search
//! directions and the preconditioner work in `T` (`f32` halves the memory traffic of the
//! Poisson solves; the biharmonic field needs `f64`). When the recurrence has drifted from the
//! true residual, CG restarts from the true one. Every reduction sums fixed bands of rows in
//! order, so the result does not depend on the number of threads.

// Lane loops index several arrays in lockstep; the index form is what vectorises.
#![allow(clippy::needless_range_loop)]

use std::ops::{Add, AddAssign, Mul, Sub, SubAssign};

use rayon::prelude::*;

use super::bands::{bands, sum_lanes, BAND, PARALLEL_CELLS};
use crate::{cancel, Result};

/// The working precision of the vectors of a solve: `f32` or `f64`.
pub(crate) trait Real:
    Copy
    + Send
    + Sync
    + Into<f64>
    + Add<Output = Self>
    + Sub<Output = Self>
    + Mul<Output = Self>
    + AddAssign
    + SubAssign
{
    const ZERO: Self;
    const ONE: Self;
    /// `v` rounded to this precision.
    fn of_f64(v: f64) -> Self;
    /// `v` in this precision (exact).
    fn of_f32(v: f32) -> Self;
}

impl Real for f32 {
    const ZERO: Self = 0.0;
    const ONE: Self = 1.0;
    #[inline]
    fn of_f64(v: f64) -> Self {
        v as f32
    }
    #[inline]
    fn of_f32(v: f32) -> Self {
        v
    }
}

impl Real for f64 {
    const ZERO: Self = 0.0;
    const ONE: Self = 1.0;
    #[inline]
    fn of_f64(v: f64) -> Self {
        v
    }
    #[inline]
    fn of_f32(v: f32) -> Self {
        f64::from(v)
    }
}

/// The matrix `A` of a solve, on vectors laid out as grid rows of the width given to [`pcg`].
pub(crate) trait Operator<T: Real, const L: usize> {
    /// `q = A p`; returns `⟨p, q⟩` per lane (summed in `f64` over bands in order).
    fn apply(&mut self, p: &[[T; L]], q: &mut [[T; L]]) -> [f64; L];
    /// The true residual `r = b − A x`, computed in `f64` and stored in `T`; returns `‖r‖²`
    /// per lane.
    fn residual(&mut self, b: &[[f64; L]], x: &[[f64; L]], r: &mut [[T; L]]) -> [f64; L];
}

/// A symmetric positive definite approximation `M⁻¹` of `A⁻¹`.
pub(crate) trait Preconditioner<T: Real, const L: usize> {
    /// `z = M⁻¹ r`; returns `⟨r, z⟩` per lane.
    fn apply(&mut self, r: &[[T; L]], z: &mut [[T; L]]) -> [f64; L];
    /// Writes a first guess for `A x = b` into `x` and returns `true`, or returns `false` to
    /// start from zero.
    fn first_guess(&mut self, _b: &[[T; L]], _x: &mut [[T; L]]) -> bool {
        false
    }
}

/// The result of [`pcg`].
pub(crate) struct Solution<const L: usize> {
    /// The iterate.
    pub x: Vec<[f64; L]>,
    /// Conjugate-gradient iterations taken.
    pub iterations: usize,
    /// Largest relative true residual `‖b − A x‖ / scale` over lanes.
    pub residual: f64,
}

/// Solves `A x = b` (vectors of grid rows `w` long) until every lane's residual is at most
/// `tol · scale[c]` or `max_iterations` iterations have run; `Err(Error::Cancelled)` once the
/// thread's work is cancelled (checked once per iteration).
///
/// The update of `x` by an iteration's step is deferred to the pass that updates the search
/// direction of the next one (the same arithmetic, one pass over the vectors less).
pub(crate) fn pcg<T: Real, const L: usize>(
    a: &mut impl Operator<T, L>,
    m: &mut impl Preconditioner<T, L>,
    b: &[[f64; L]],
    w: usize,
    scale: [f64; L],
    tol: f64,
    max_iterations: usize,
) -> Result<Solution<L>> {
    let n = b.len();
    let mut r: Vec<[T; L]> = b.iter().map(|v| v.map(T::of_f64)).collect();
    let mut z = vec![[T::ZERO; L]; n];
    let mut p = vec![[T::ZERO; L]; n];
    let mut q = vec![[T::ZERO; L]; n];
    let done = |rr: [f64; L]| (0..L).all(|c| rr[c].sqrt() <= tol * scale[c]);
    let (mut x, mut rr);
    if m.first_guess(&r, &mut z) {
        // The guess's residual in T like the recurrence (the f64 check at the end decides).
        x = z
            .iter()
            .map(|v| v.map(Into::into))
            .collect::<Vec<[f64; L]>>();
        a.apply(&z, &mut q);
        rr = update_residual(&mut r, &q, w, [T::ONE; L]);
        if done(rr) {
            rr = a.residual(b, &x, &mut r);
        }
    } else {
        x = vec![[0f64; L]; n];
        rr = norm2(b, w);
    }
    let mut it = 0;
    loop {
        if done(rr) || it >= max_iterations {
            break;
        }
        let mut rz = m.apply(&r, &mut z);
        // p = z; z's buffer is overwritten by the next preconditioner step before it is read.
        std::mem::swap(&mut p, &mut z);
        loop {
            let pq = a.apply(&p, &mut q);
            let alpha: [f64; L] = std::array::from_fn(|c| {
                if pq[c] > 0.0 && rz[c] > 0.0 {
                    rz[c] / pq[c]
                } else {
                    0.0
                }
            });
            rr = update_residual(&mut r, &q, w, alpha.map(T::of_f64));
            it += 1;
            cancel::check()?;
            if done(rr) || it >= max_iterations {
                step(&mut x, &mut p, &z, w, alpha, None);
                break;
            }
            let rz_new = m.apply(&r, &mut z);
            let beta: [T; L] = std::array::from_fn(|c| {
                T::of_f64(if rz[c] > 0.0 { rz_new[c] / rz[c] } else { 0.0 })
            });
            rz = rz_new;
            step(&mut x, &mut p, &z, w, alpha, Some(beta));
        }
        rr = a.residual(b, &x, &mut r);
        if done(rr) || it >= max_iterations {
            break;
        }
    }
    let residual = (0..L).map(|c| rr[c].sqrt() / scale[c]).fold(0.0, f64::max);
    Ok(Solution {
        x,
        iterations: it,
        residual,
    })
}

/// `‖b‖²` per lane, summed over bands of rows `w` long.
fn norm2<const L: usize>(b: &[[f64; L]], w: usize) -> [f64; L] {
    let mut s = [0f64; L];
    for band in b.chunks(BAND * w) {
        let mut t = [0f64; L];
        for v in band {
            for c in 0..L {
                t[c] += v[c] * v[c];
            }
        }
        for c in 0..L {
            s[c] += t[c];
        }
    }
    s
}

/// A band of the iterate (`f64`) and of the search direction.
type StepBand<'a, T, const L: usize> = (&'a mut [[f64; L]], &'a mut [[T; L]]);

/// `x += α p` (the step of the previous iteration) and then `p = z + β p`, in one pass.
fn step<T: Real, const L: usize>(
    x: &mut [[f64; L]],
    p: &mut [[T; L]],
    z: &[[T; L]],
    w: usize,
    alpha: [f64; L],
    beta: Option<[T; L]>,
) {
    let job = |(bi, (xb, pb)): (usize, StepBand<'_, T, L>)| {
        let zb = &z[bi * BAND * w..];
        for ((xi, pi), zi) in xb.iter_mut().zip(pb.iter_mut()).zip(zb) {
            for c in 0..L {
                xi[c] += alpha[c] * pi[c].into();
            }
            if let Some(beta) = beta {
                for c in 0..L {
                    pi[c] = zi[c] + beta[c] * pi[c];
                }
            }
        }
    };
    let parallel = x.len() >= PARALLEL_CELLS;
    let chunks = x.chunks_mut(BAND * w).zip(p.chunks_mut(BAND * w));
    if parallel {
        chunks
            .collect::<Vec<_>>()
            .into_par_iter()
            .enumerate()
            .for_each(job);
    } else {
        chunks.enumerate().for_each(job);
    }
}

/// `r −= α q`; returns `‖r‖²` per lane.
fn update_residual<T: Real, const L: usize>(
    r: &mut [[T; L]],
    q: &[[T; L]],
    w: usize,
    alpha: [T; L],
) -> [f64; L] {
    let parts = bands(r, w, |bi, rb| {
        let mut s = [0f64; L];
        let qb = &q[bi * BAND * w..];
        for (ri, qi) in rb.iter_mut().zip(qb) {
            for c in 0..L {
                ri[c] -= alpha[c] * qi[c];
                let v: f64 = ri[c].into();
                s[c] += v * v;
            }
        }
        s
    });
    sum_lanes(&parts)
}
