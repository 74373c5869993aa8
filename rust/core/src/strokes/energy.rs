//! The compositing energy of pairs of pieces: the minimum cut of their overlap under Luo et
//! al.'s Eqs. 1–2, for the dynamic programme that chooses where along the source each target
//! sample takes its piece.

use rayon::prelude::*;

use super::fetch::Piece;
use crate::error::invalid;
use crate::image::Image;
use crate::seams::{seam, SeamCost, SeamInput};
use crate::{cancel, Result};

/// The two pieces' colours (RGB) and supports on the intersection of their boxes plus a
/// one-pixel ring (so overlap pixels on the intersection's edge see which piece goes on
/// beyond it); `None` when the supports do not meet.
struct Overlap {
    h: usize,
    w: usize,
    colours: [Vec<f32>; 2],
    masks: [Vec<bool>; 2],
}

fn overlap(p: &Piece, q: &Piece) -> Option<Overlap> {
    let y0 = p.y0.max(q.y0) - 1;
    let x0 = p.x0.max(q.x0) - 1;
    let y1 = (p.y0 + p.h as i64).min(q.y0 + q.h as i64) + 1;
    let x1 = (p.x0 + p.w as i64).min(q.x0 + q.w as i64) + 1;
    if y1 - y0 <= 2 || x1 - x0 <= 2 {
        return None;
    }
    let (h, w) = ((y1 - y0) as usize, (x1 - x0) as usize);
    let mut colours = [vec![0f32; h * w * 3], vec![0f32; h * w * 3]];
    let mut masks = [vec![false; h * w], vec![false; h * w]];
    for (k, piece) in [p, q].into_iter().enumerate() {
        for r in 0..h {
            let y = y0 + r as i64 - piece.y0;
            if y < 0 || y >= piece.h as i64 {
                continue;
            }
            for c in 0..w {
                let x = x0 + c as i64 - piece.x0;
                if x < 0 || x >= piece.w as i64 {
                    continue;
                }
                let j = y as usize * piece.w + x as usize;
                let i = r * w + c;
                masks[k][i] = piece.support[j];
                colours[k][i * 3..i * 3 + 3].copy_from_slice(&piece.rgba[j * 4..j * 4 + 3]);
            }
        }
    }
    if !masks[0].iter().zip(&masks[1]).any(|(a, b)| *a && *b) {
        return None;
    }
    Some(Overlap {
        h,
        w,
        colours,
        masks,
    })
}

/// The energy of the minimum-cost seam between two pieces in the target frame: Luo's cost
/// (`min(d(x), d(y)) / G(x, y)`, `d` the fourth power of the colour difference) over their
/// overlap, with the data term of 10000 tying overlap pixels that border only one piece to
/// it (Eq. 1). Pieces whose supports do not meet cost nothing.
pub fn seam_energy(p: &Piece, q: &Piece) -> Result<f64> {
    let Some(Overlap {
        h,
        w,
        colours,
        masks,
    }) = overlap(p, q)
    else {
        return Ok(0.0);
    };
    let region: Vec<bool> = masks[0]
        .iter()
        .zip(&masks[1])
        .map(|(a, b)| *a && *b)
        .collect();
    let a = Image::new("a", &colours[0], h, w, 3)?;
    let b = Image::new("b", &colours[1], h, w, 3)?;
    let mut inp = SeamInput::new(a, b, &region);
    inp.a_mask = Some(&masks[0]);
    inp.b_mask = Some(&masks[1]);
    inp.cost = SeamCost::Luo;
    inp.border_weight = SeamCost::Luo.default_border_weight();
    Ok(seam(&inp)?.energy)
}

/// [`seam_energy`] of every pair `(i, j)` of `pieces`, in parallel.
pub fn pair_energies(pieces: &[Piece], pairs: &[(usize, usize)]) -> Result<Vec<f64>> {
    if let Some(&(i, j)) = pairs
        .iter()
        .find(|(i, j)| *i >= pieces.len() || *j >= pieces.len())
    {
        return Err(invalid(
            "pairs",
            format!(
                "pair ({i}, {j}) names a piece beyond the {} given",
                pieces.len()
            ),
        ));
    }
    let out = pairs
        .par_iter()
        .map(|&(i, j)| {
            if cancel::cancelled() {
                Ok(0.0)
            } else {
                seam_energy(&pieces[i], &pieces[j])
            }
        })
        .collect::<Result<Vec<_>>>()?;
    cancel::check()?;
    Ok(out)
}

#[cfg(test)]
mod tests {
    use super::*;

    fn piece(x0: i64, w: usize, value: impl Fn(usize, usize) -> f32) -> Piece {
        let h = 6;
        let mut rgba = vec![0f32; h * w * 4];
        for r in 0..h {
            for c in 0..w {
                let o = (r * w + c) * 4;
                rgba[o..o + 3].fill(value(r, c));
                rgba[o + 3] = 1.0;
            }
        }
        Piece {
            y0: 0,
            x0,
            h,
            w,
            rgba,
            support: vec![true; h * w],
            widths: [3.0, 3.0],
        }
    }

    #[test]
    #[allow(clippy::float_cmp)] // equal colours make every edge cost exactly zero
    fn equal_overlaps_cost_nothing_and_apart_pieces_too() {
        let ramp = |_r: usize, c: usize| c as f32 / 20.0;
        let p = piece(0, 10, ramp);
        let q = piece(5, 10, |r, c| ramp(r, c + 5));
        assert_eq!(seam_energy(&p, &q).unwrap(), 0.0);
        let far = piece(30, 10, ramp);
        assert_eq!(pair_energies(&[p, q, far], &[(0, 2)]).unwrap(), vec![0.0]);
    }

    #[test]
    fn energy_is_the_seam_of_the_whole_frame() {
        // The overlap's crop must give the energy of the seam over the pieces' union (framed by
        // a ring of neither), where each overlap pixel sees the piece that continues beyond it.
        let p = piece(0, 10, |r, c| ((r * 7 + c * 3) % 5) as f32 / 5.0);
        let q = piece(4, 10, |r, c| ((r * 2 + c * 5) % 7) as f32 / 7.0);
        let e = seam_energy(&p, &q).unwrap();
        let (h, w) = (8, 16);
        let mut colours = [vec![0f32; h * w * 3], vec![0f32; h * w * 3]];
        let mut masks = [vec![false; h * w], vec![false; h * w]];
        for (k, piece) in [&p, &q].into_iter().enumerate() {
            for r in 0..piece.h {
                for c in 0..piece.w {
                    let i = (r + 1) * w + c + 1 + piece.x0 as usize;
                    let j = r * piece.w + c;
                    masks[k][i] = true;
                    colours[k][i * 3..i * 3 + 3].copy_from_slice(&piece.rgba[j * 4..j * 4 + 3]);
                }
            }
        }
        let region: Vec<bool> = masks[0]
            .iter()
            .zip(&masks[1])
            .map(|(a, b)| *a && *b)
            .collect();
        let mut inp = SeamInput::new(
            Image::new("a", &colours[0], h, w, 3).unwrap(),
            Image::new("b", &colours[1], h, w, 3).unwrap(),
            &region,
        );
        inp.a_mask = Some(&masks[0]);
        inp.b_mask = Some(&masks[1]);
        inp.cost = SeamCost::Luo;
        inp.border_weight = 10_000.0;
        let full = seam(&inp).unwrap();
        assert!(full.tied.0 > 0 && full.tied.1 > 0);
        assert!(e > 0.0);
        assert!(
            (e - full.energy).abs() <= 1e-9 * full.energy,
            "{e} vs {}",
            full.energy
        );
        assert!(pair_energies(&[p], &[(0, 1)]).is_err());
    }
}
