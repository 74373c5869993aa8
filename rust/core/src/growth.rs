//! The choice of one growth step of a branching structure (Sibbing et al. 2010, §4.4–4.5),
//! after the bending model has scored every candidate extension: the density and guidance
//! terms, the frame, the planarity test, and the `c` best valid candidates among which the
//! caller draws.

use crate::colonisation::{check_rays, density_ray_max, field_ray_max, DensityView, Rays, Skip};
use crate::crossings::crosses;
use crate::error::{invalid, Result};

/// A model's candidate extensions, relative to a tip at the origin heading along +x.
#[derive(Clone, Copy)]
pub struct Candidates<'a> {
    /// `C × m` points `x, y` of each candidate's path (flat).
    pub relative: &'a [f64],
    pub m: usize,
    /// The ray each candidate's density and guidance are read along.
    pub ray_of: &'a [usize],
}

/// The space-colonisation term: the density map, the parent pixels a child ignores, and the
/// `ρ` of the image border when it counts as structure.
#[derive(Clone, Copy)]
pub struct Colonisation<'a> {
    pub view: DensityView<'a>,
    pub skip: Option<Skip>,
    pub border_rho: Option<f64>,
}

/// Where and how the tip grows.
#[derive(Clone, Copy)]
pub struct Tip {
    pub point: [f64; 2],
    /// The heading's cosine and sine (counter-clockwise on screen, `y` pointing down).
    pub cos: f64,
    pub sin: f64,
}

impl Tip {
    /// Point `k` of a candidate's path turned to the heading and moved to the tip.
    #[inline]
    fn place(&self, r: &[f64]) -> [f64; 2] {
        [
            self.point[0] + self.cos * r[0] + self.sin * r[1],
            self.point[1] - self.sin * r[0] + self.cos * r[1],
        ]
    }
}

/// Everything one step's choice reads besides the candidates' qualities.
pub struct Step<'a> {
    pub candidates: Candidates<'a>,
    pub tip: Tip,
    /// The image, `(h, w)`: every point of a valid path lies in `0 ..= w − 1`, `0 ..= h − 1`.
    pub shape: (usize, usize),
    /// The rays, as unit directions for this heading.
    pub rays: Rays<'a>,
    pub colonisation: Option<Colonisation<'a>>,
    /// The guidance map `G` (§4.5), `h × w`.
    pub guide: Option<&'a [f64]>,
    /// `(s, 4)` rows `x0, y0, x1, y1` of the structure so far.
    pub segments: &'a [f64],
    /// The `ε` of §4.4: qualities are divided by `D + ε` and `G + ε`.
    pub eps: f64,
}

/// The first `count` valid candidates by decreasing quality (ties: lower index first) and their
/// qualities: `log Q − log(D + ε) − log(G + ε)` with `D` and `G` the largest density and
/// guidance along the candidate's ray. Valid means a finite quality, a path inside the image,
/// and no proper crossing with `segments`.
///
/// Only the candidates tried are turned into paths and tested: the best few first, the rest
/// sorted only when those do not hold `count` valid ones.
pub fn choose(step: &Step<'_>, quality: &[f64], count: usize) -> Result<(Vec<usize>, Vec<f64>)> {
    let Candidates {
        relative,
        m,
        ray_of,
    } = step.candidates;
    let c = quality.len();
    if m == 0 || relative.len() != 2 * m * c || ray_of.len() != c {
        return Err(invalid(
            "candidates",
            format!(
                "expected {c} paths of m ≥ 1 points and {c} ray indices, got {} coordinates and {} indices",
                relative.len(),
                ray_of.len()
            ),
        ));
    }
    check_rays(&step.rays)?;
    let n_rays = step.rays.directions.len();
    if ray_of.iter().any(|&r| r >= n_rays) {
        return Err(invalid(
            "ray_of",
            format!("expected ray indices below {n_rays}"),
        ));
    }
    if step.segments.len() % 4 != 0 {
        return Err(invalid(
            "segments",
            format!("expected (s, 4) coordinates, got {}", step.segments.len()),
        ));
    }
    let (h, w) = step.shape;
    let mut penalty = vec![0.0; n_rays];
    if let Some(col) = step.colonisation {
        let d = density_ray_max(col.view, &step.rays, col.skip, col.border_rho)?;
        penalty = d.iter().map(|v| (v + step.eps).ln()).collect();
    }
    let guide_penalty = match step.guide {
        Some(g) => Some(
            field_ray_max(g, h, w, &step.rays)?
                .iter()
                .map(|v| (v + step.eps).ln())
                .collect::<Vec<f64>>(),
        ),
        None => None,
    };
    let q: Vec<f64> = (0..c)
        .map(|i| {
            let r = ray_of[i];
            let v = quality[i] - penalty[r];
            guide_penalty.as_ref().map_or(v, |g| v - g[r])
        })
        .collect();

    // the segments that can meet any path: within the paths' reach of the tip
    let reach = relative
        .chunks_exact(2)
        .map(|p| p[0].abs().max(p[1].abs()))
        .fold(0.0, f64::max);
    let tip = step.tip.point;
    let (lo, hi) = (
        [tip[0] - reach, tip[1] - reach],
        [tip[0] + reach, tip[1] + reach],
    );
    let near: Vec<([f64; 2], [f64; 2])> = step
        .segments
        .chunks_exact(4)
        .filter(|s| {
            s[0].max(s[2]) >= lo[0]
                && s[0].min(s[2]) <= hi[0]
                && s[1].max(s[3]) >= lo[1]
                && s[1].min(s[3]) <= hi[1]
        })
        .map(|s| ([s[0], s[1]], [s[2], s[3]]))
        .collect();
    let (xmax, ymax) = (w as f64 - 1.0, h as f64 - 1.0);
    let valid = |i: usize| {
        let mut prev = tip;
        for r in relative[2 * i * m..2 * (i + 1) * m].chunks_exact(2) {
            let p = step.tip.place(r);
            if !(p[0] >= 0.0 && p[0] <= xmax && p[1] >= 0.0 && p[1] <= ymax)
                || near.iter().any(|&(a, b)| crosses(prev, p, a, b))
            {
                return false;
            }
            prev = p;
        }
        true
    };

    let mut order: Vec<usize> = (0..c).filter(|&i| q[i].is_finite()).collect();
    // a strict total order (quality down, index up): the partial selection below and a full
    // sort give the same sequence
    let before = |a: &usize, b: &usize| q[*b].total_cmp(&q[*a]).then(a.cmp(b));
    let head = (4 * count).max(16).min(order.len());
    if head > 0 && head < order.len() {
        order.select_nth_unstable_by(head - 1, before);
    }
    order[..head].sort_unstable_by(before);
    let mut chosen: Vec<usize> = order[..head]
        .iter()
        .copied()
        .filter(|&i| valid(i))
        .take(count)
        .collect();
    if chosen.len() < count && head < order.len() {
        order[head..].sort_unstable_by(before);
        let more = count - chosen.len();
        chosen.extend(
            order[head..]
                .iter()
                .copied()
                .filter(|&i| valid(i))
                .take(more),
        );
    }
    let qualities = chosen.iter().map(|&i| q[i]).collect();
    Ok((chosen, qualities))
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A small pseudo-random generator for test data.
    struct Lcg(u64);
    impl Lcg {
        fn next(&mut self) -> f64 {
            self.0 = self
                .0
                .wrapping_mul(6_364_136_223_846_793_005)
                .wrapping_add(1_442_695_040_888_963_407);
            (self.0 >> 11) as f64 / (1u64 << 53) as f64
        }
    }

    /// The choice by brute force: every path, every test, a full stable sort.
    fn brute(step: &Step<'_>, quality: &[f64], count: usize) -> (Vec<usize>, Vec<f64>) {
        let Candidates {
            relative,
            m,
            ray_of,
        } = step.candidates;
        let (h, w) = step.shape;
        let dens = step
            .colonisation
            .map(|c| density_ray_max(c.view, &step.rays, c.skip, c.border_rho).unwrap());
        let guide = step
            .guide
            .map(|g| field_ray_max(g, h, w, &step.rays).unwrap());
        let mut ok: Vec<(usize, f64)> = Vec::new();
        for (i, &q0) in quality.iter().enumerate() {
            let mut q = q0;
            if let Some(d) = &dens {
                q -= (d[ray_of[i]] + step.eps).ln();
            }
            if let Some(g) = &guide {
                q -= (g[ray_of[i]] + step.eps).ln();
            }
            let pts: Vec<[f64; 2]> = relative[2 * i * m..2 * (i + 1) * m]
                .chunks_exact(2)
                .map(|r| step.tip.place(r))
                .collect();
            let inside = pts.iter().all(|p| {
                p[0] >= 0.0 && p[0] <= w as f64 - 1.0 && p[1] >= 0.0 && p[1] <= h as f64 - 1.0
            });
            let mut prev = step.tip.point;
            let mut crossed = false;
            for &p in &pts {
                for s in step.segments.chunks_exact(4) {
                    crossed |= crosses(prev, p, [s[0], s[1]], [s[2], s[3]]);
                }
                prev = p;
            }
            if q.is_finite() && inside && !crossed {
                ok.push((i, q));
            }
        }
        ok.sort_by(|a, b| b.1.partial_cmp(&a.1).unwrap());
        ok.truncate(count);
        ok.into_iter().unzip()
    }

    #[test]
    fn the_choice_is_the_brute_force_one() {
        let mut rng = Lcg(7);
        let (h, w) = (60, 80);
        let (c, m) = (300, 3);
        let relative: Vec<f64> = (0..c * m * 2).map(|_| rng.next() * 24.0 - 8.0).collect();
        let n_rays = 17;
        let ray_of: Vec<usize> = (0..c).map(|i| i % n_rays).collect();
        let dirs: Vec<[f64; 2]> = (0..n_rays)
            .map(|k| {
                let a = k as f64 * 0.37;
                [a.cos(), -a.sin()]
            })
            .collect();
        let density: Vec<f32> = (0..h * w).map(|_| (rng.next() as f32).powi(3)).collect();
        let owner_branch: Vec<i32> = (0..h * w).map(|i| (i % 3) as i32).collect();
        let owner_vertex: Vec<i32> = (0..h * w).map(|i| (i % 11) as i32).collect();
        let guide: Vec<f64> = (0..h * w).map(|_| rng.next()).collect();
        // qualities with ties and non-finite values
        let mut quality: Vec<f64> = (0..c).map(|_| (rng.next() * 8.0).round() / 4.0).collect();
        quality[3] = f64::NEG_INFINITY;
        quality[4] = f64::NAN;
        let segments: Vec<f64> = (0..40)
            .flat_map(|_| {
                let (x, y) = (rng.next() * 80.0, rng.next() * 60.0);
                [
                    x,
                    y,
                    x + rng.next() * 10.0 - 5.0,
                    y + rng.next() * 10.0 - 5.0,
                ]
            })
            .collect();
        let view = DensityView {
            density: &density,
            owner_branch: &owner_branch,
            owner_vertex: &owner_vertex,
            height: h,
            width: w,
        };
        for (case, (tip, heading)) in [([40.0, 30.0], 0.3), ([3.0, 5.0], 2.0), ([77.0, 58.0], -1.0)]
            .into_iter()
            .enumerate()
        {
            let rays = Rays {
                tip,
                directions: &dirs,
                length: 12.0,
                samples: 6,
            };
            let colonisation = Some(Colonisation {
                view,
                skip: Some(Skip {
                    branch: 1,
                    vertex: 5,
                    near: 2,
                    floor: 0.25,
                }),
                border_rho: (case == 1).then_some(4.0),
            });
            let step = Step {
                candidates: Candidates {
                    relative: &relative,
                    m,
                    ray_of: &ray_of,
                },
                tip: Tip {
                    point: tip,
                    cos: f64::cos(heading),
                    sin: f64::sin(heading),
                },
                shape: (h, w),
                rays,
                colonisation,
                guide: (case != 2).then_some(&guide[..]),
                segments: &segments,
                eps: 1e-3,
            };
            for count in [1, 2, 5, 40, 400] {
                let got = choose(&step, &quality, count).unwrap();
                let want = brute(&step, &quality, count);
                assert_eq!(got.0, want.0, "case {case}, count {count}");
                assert_eq!(got.1, want.1);
                assert!(!got.0.is_empty());
            }
        }
    }

    #[test]
    fn bad_candidates_are_errors() {
        let dirs = [[1.0, 0.0]];
        let step =
            |relative: &'static [f64], ray_of: &'static [usize], segments: &'static [f64]| Step {
                candidates: Candidates {
                    relative,
                    m: 1,
                    ray_of,
                },
                tip: Tip {
                    point: [1.0, 1.0],
                    cos: 1.0,
                    sin: 0.0,
                },
                shape: (4, 4),
                rays: Rays {
                    tip: [1.0, 1.0],
                    directions: &dirs,
                    length: 1.0,
                    samples: 1,
                },
                colonisation: None,
                guide: None,
                segments,
                eps: 1e-3,
            };
        assert_eq!(
            choose(&step(&[1.0, 0.0], &[0], &[]), &[0.0], 1).unwrap().0,
            vec![0]
        );
        assert!(choose(&step(&[1.0], &[0], &[]), &[0.0], 1).is_err());
        assert!(choose(&step(&[1.0, 0.0], &[1], &[]), &[0.0], 1).is_err());
        assert!(choose(&step(&[1.0, 0.0], &[0], &[0.0; 3]), &[0.0], 1).is_err());
        // a path leaving the image is never chosen
        assert!(choose(&step(&[5.0, 0.0], &[0], &[]), &[0.0], 1)
            .unwrap()
            .0
            .is_empty());
    }
}
