//! Texture-by-numbers (Laitoch 2018, §3.3–3.4, after Fan, Qi, Wang, Wen 2012, "Parallel
//! texture-by-numbers"): given an exemplar `A'`, its label map `A` and an output label map
//! `B`, synthesise `B'` so that it looks like `A'` where `B` looks like `A`.
//!
//! `B'` is an image of references (flat exemplar indices). Over a pyramid of reference images
//! (§3.3.2, [`pyramid`]), starting from a random or "smart" initialisation at the coarsest
//! level (§3.4, [`init`]), each level runs `iterations` steps of the discrete k-coherence
//! solver of §3.3.5:
//!
//! 1. k-coherence candidate sets (§3.3.6) from the current references and the exemplar's
//!    `(k − 1)` nearest patches ([`crate::knn`]);
//! 2. M-step (Eq. 3.4): on a sparse grid `X†` of output pixels (every other row and column;
//!    all pixels at the finest level), the candidate whose `N_lr`
//!    neighbourhood in `concat(A, A')` is nearest to the output's in `concat(B, B'_ref)`;
//!    phloem adds a PatchMatch-style random search (Barnes et al. 2009) among same-label
//!    exemplar pixels around the best candidate;
//! 3. E-step (Eq. 3.5): every output pixel chooses among the forward-shifted matches that
//!    cover it, weighted by their match distances (after Kwatra et al. 2005's robust
//!    optimisation): the candidate nearest to their average, their weighted medoid, or the
//!    medoid until the last finest iteration (see [`Selection`]).
//!
//! The distance is the squared L2 of Eq. 3.3: the exemplar's channels (features such as a
//! feature distance map ride along as weighted channels) plus `w` per label mismatch (labels
//! are one-hot channels scaled by `sqrt(w / 2)`). phloem adds a hard label constraint: every
//! output pixel references an exemplar pixel of its own label. An optional round of graph-cut
//! compositing ([`composite`]) after the finest level grows whole exemplar pieces, and with
//! stand-ins lets them run across output label boundaries the exemplar lacks.
//!
//! Layout: this file holds the parameters, their validation and the pyramid driver; the
//! private `solver` module one level's M-step and E-step.

pub mod composite;
pub mod init;
pub mod pyramid;
mod solver;

use crate::error::{invalid, Result};
use crate::image::{prescale, Image};
use crate::knn::shift;
use crate::patch::NONE;
use pyramid::{level_sizes, upsample_refs, Step};
use solver::{out_index, ExLevel, Level};

/// Initialisation of the coarsest level (§3.4).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Init {
    /// Flood-fill region growth under Eq. 3.6 (§3.4.2).
    Smart,
    /// Random same-label exemplar pixels (§3.4.1).
    Random,
}

/// How the E-step turns a pixel's votes (the forward-shifted matches covering it) into its
/// reference.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Selection {
    /// The same-label vote or candidate nearest to the votes' weighted average (Eq. 3.5).
    /// Most patch-coherent, but where the votes disagree it favours mid-tones: softer output.
    Average,
    /// The weighted medoid of the same-label votes: the vote with the least weighted sum of
    /// distances to the others. Keeps the exemplar's contrast and fine detail, but is less
    /// patch-coherent.
    Medoid,
    /// [`Selection::Medoid`] at every iteration but the finest level's last, which takes
    /// [`Selection::Average`]: sharpness and coherence in between.
    Hybrid,
}

/// Parameters of [`by_numbers`].
///
/// [`TbnParams::default`] is what a Rust caller gets, and each field's doc names its Rust
/// default: medoid selection, no compositing, no stand-ins. phloem's Python wrapper
/// (`phloem.texture.by_numbers`) passes every field explicitly with defaults of its own.
#[derive(Clone, Debug)]
pub struct TbnParams {
    /// Neighbourhood side, odd. Default 7 (with `k = 1`; see `docs/engines/tbn.md`).
    pub patch_size: usize,
    /// k of k-coherence: each coherence candidate brings its `k − 1` nearest exemplar patches.
    /// Default 1 (coherence candidates only, no k-NN table).
    pub k: usize,
    /// Weight `w` of a label mismatch in the distance (Eq. 3.3). Default 3 (the thesis' bark
    /// value; Fan et al. used 1).
    pub label_weight: f32,
    /// Pyramid levels; `None` chooses as many as keep the coarsest images at least
    /// [`MIN_COARSE_SIDE`] pixels wide (at most 5). Default `None`.
    pub levels: Option<usize>,
    /// Solver iterations at the finest level (`maxIterTime`); the coarser levels run
    /// [`COARSE_EXTRA_ITERATIONS`] more. Default 3.
    pub iterations: usize,
    /// Initialisation. Default [`Init::Smart`].
    pub init: Init,
    /// E-step selection. Default [`Selection::Medoid`] (the only one that keeps the exemplar's
    /// sharpness; see [`Selection`]).
    pub selection: Selection,
    /// Rounds of graph-cut compositing ([`composite`]) after the finest level: coherent
    /// pieces of the exemplar grow, with seams where their copies agree. 0 (the default)
    /// leaves the solver's result as it is.
    pub composite: usize,
    /// Weight `W` of label stand-ins in the compositing: a pixel may take an offset whose
    /// copy has another label if it shows that copy's stand-in (the exemplar pixel of its own
    /// label nearest in colour and in mean colour over a patch), at a data cost of `W` times
    /// that distance (see [`composite`]). Infinite (the default) forbids such offsets.
    pub stand_in_weight: f32,
    /// Exemplar channels the compositing seams compare (the first `seam_channels`; 0, the
    /// default, = all), e.g. the colour channels without a feature distance map.
    pub seam_channels: usize,
    /// Forward shifts that leave the exemplar wrap around (true) or are dropped. Default true.
    pub wrap: bool,
    /// Output neighbourhoods wrap around the output's borders, so it tiles. Default false.
    pub tileable: bool,
    /// Random-search samples per M-step pixel: radius halving from the exemplar size. Default
    /// true.
    pub random_search: bool,
    /// Seed of every random choice.
    pub seed: u64,
}

impl Default for TbnParams {
    fn default() -> Self {
        Self {
            patch_size: 7,
            k: 1,
            label_weight: 3.0,
            levels: None,
            iterations: 3,
            init: Init::Smart,
            selection: Selection::Medoid,
            composite: 0,
            stand_in_weight: f32::INFINITY,
            seam_channels: 0,
            wrap: true,
            tileable: false,
            random_search: true,
            seed: 0,
        }
    }
}

/// The coarsest level of the automatic pyramid keeps at least this many pixels across.
pub const MIN_COARSE_SIDE: usize = 40;
/// Most pyramid levels chosen automatically.
pub const MAX_AUTO_LEVELS: usize = 5;
/// Extra solver iterations at every level but the finest: they are cheap (a quarter of the
/// pixels or fewer) and the coarse layout decides the fine coherence.
pub const COARSE_EXTRA_ITERATIONS: usize = 2;
/// Inputs of [`by_numbers`].
#[derive(Clone, Copy, Debug)]
pub struct TbnInput<'a> {
    /// `A'`: the exemplar, any channels (colour, extra maps, feature distance maps).
    pub exemplar: Image<'a>,
    /// Per-channel weights of the exemplar's channels (default all 1).
    pub weights: Option<&'a [f32]>,
    /// `A`: compact labels `0..n` of the exemplar, `h × w`.
    pub labels_in: &'a [u32],
    /// `B`: labels of the output, `out_h × out_w`; each must occur in `labels_in`.
    pub labels_out: &'a [u32],
    /// Output height.
    pub out_h: usize,
    /// Output width.
    pub out_w: usize,
}

/// The result: an image of references.
#[derive(Clone, Debug)]
pub struct Tbn {
    /// Output height.
    pub h: usize,
    /// Output width.
    pub w: usize,
    /// `h × w` flat indices into the exemplar (`row · exemplar_w + col`).
    pub refs: Vec<u32>,
}

/// The forward-shifted `N_lmr` neighbourhood of output pixel `(y, x)` (§3.3.1, Fig. 3.1): for
/// every offset `o` of the `patch_size` window in row-major order, the reference of the
/// output pixel at `(y, x) + o` moved by `−o`, i.e. the exemplar pixel that would continue it
/// at `(y, x)`. Entries are [`NONE`] outside the output (unless `tileable`), for [`NONE`]
/// references, and for shifts leaving the exemplar without `wrap`.
#[must_use]
pub fn forward_shifted(
    refs: &[u32],
    (h, w): (usize, usize),
    (y, x): (usize, usize),
    patch_size: usize,
    (eh, ew): (usize, usize),
    wrap: bool,
    tileable: bool,
) -> Vec<u32> {
    let r = (patch_size / 2) as i64;
    let mut out = Vec::with_capacity(patch_size * patch_size);
    for dy in -r..=r {
        for dx in -r..=r {
            out.push(
                match out_index(y as i64 + dy, x as i64 + dx, h, w, tileable) {
                    Some(j) => shift(refs[j], -dy, -dx, eh, ew, wrap),
                    None => NONE,
                },
            );
        }
    }
    out
}

fn check(input: &TbnInput<'_>, params: &TbnParams) -> Result<usize> {
    let p = params.patch_size;
    if p == 0 || p % 2 == 0 {
        return Err(invalid(
            "patch_size",
            format!("expected an odd size >= 1, got {p}"),
        ));
    }
    if params.k == 0 {
        return Err(invalid("k", "expected k >= 1, got 0"));
    }
    if params.iterations == 0 {
        return Err(invalid(
            "iterations",
            "expected at least 1 iteration, got 0",
        ));
    }
    if !(params.label_weight.is_finite() && params.label_weight >= 0.0) {
        return Err(invalid(
            "label_weight",
            format!("expected a finite value >= 0, got {}", params.label_weight),
        ));
    }
    if params.levels == Some(0) {
        return Err(invalid("levels", "expected at least 1 level, got 0"));
    }
    if params.stand_in_weight.is_nan() || params.stand_in_weight < 0.0 {
        return Err(invalid(
            "stand_in_weight",
            format!(
                "expected a value >= 0 (inf: none), got {}",
                params.stand_in_weight
            ),
        ));
    }
    let ex = &input.exemplar;
    if ex.h.min(ex.w) < p {
        return Err(invalid(
            "exemplar",
            format!(
                "the {}×{} exemplar is smaller than patch_size = {p}",
                ex.h, ex.w
            ),
        ));
    }
    if input.out_h.min(input.out_w) < p {
        return Err(invalid(
            "labels_out",
            format!(
                "the {}×{} output is smaller than patch_size = {p}",
                input.out_h, input.out_w
            ),
        ));
    }
    if input.labels_in.len() != ex.h * ex.w {
        return Err(invalid(
            "labels_in",
            format!(
                "expected {}×{} labels to match the exemplar, got {}",
                ex.h,
                ex.w,
                input.labels_in.len()
            ),
        ));
    }
    if input.labels_out.len() != input.out_h * input.out_w {
        return Err(invalid(
            "labels_out",
            format!(
                "expected {}×{} labels, got {}",
                input.out_h,
                input.out_w,
                input.labels_out.len()
            ),
        ));
    }
    ex.check_finite("exemplar")?;
    let n = input.labels_in.iter().max().map_or(0, |m| *m as usize + 1);
    if n > 4096 {
        return Err(invalid(
            "labels_in",
            format!("expected compact labels below 4096, got {}", n - 1),
        ));
    }
    let mut present = vec![false; n];
    for &l in input.labels_in {
        present[l as usize] = true;
    }
    if let Some(bad) = input
        .labels_out
        .iter()
        .find(|&&l| l as usize >= n || !present[l as usize])
    {
        return Err(invalid(
            "labels_out",
            format!("label {bad} does not occur in labels_in"),
        ));
    }
    Ok(n)
}

/// Solver iterations at pyramid level `l` (0 the finest): `iterations`, plus
/// [`COARSE_EXTRA_ITERATIONS`] at the coarser levels.
#[must_use]
pub fn level_iterations(iterations: usize, l: usize) -> usize {
    if l == 0 {
        iterations
    } else {
        iterations + COARSE_EXTRA_ITERATIONS
    }
}

/// Pyramid levels: as many as keep the coarsest exemplar and output `MIN_COARSE_SIDE` wide.
fn auto_levels(min_side: usize) -> usize {
    let mut n = 1;
    while n < MAX_AUTO_LEVELS && min_side.div_ceil(1 << n) >= MIN_COARSE_SIDE {
        n += 1;
    }
    n
}

/// Synthesises an image of references by texture-by-numbers (see the module docs).
///
/// `progress(done, total)` is called after every solver iteration.
///
/// # Errors
/// [`crate::Error::InvalidArgument`] naming the parameter for bad sizes, labels or values.
///
/// # Panics
/// Never on checked input (the pyramid always holds its finest level).
pub fn by_numbers(
    input: &TbnInput<'_>,
    params: &TbnParams,
    progress: Option<&(dyn Fn(usize, usize) + Sync)>,
) -> Result<Tbn> {
    let n_labels = check(input, params)?;
    let ex = &input.exemplar;
    let (oh, ow) = (input.out_h, input.out_w);
    let p = params.patch_size;
    let min_side = ex.h.min(ex.w).min(oh).min(ow);
    let mut levels = params.levels.unwrap_or_else(|| auto_levels(min_side));
    // Coarsest sizes must still hold a patch.
    while levels > 1 && level_sizes(min_side, levels)[levels - 1] < p {
        levels -= 1;
    }

    // Augmented full-resolution exemplar.
    let c0 = ex.c;
    let ca = c0 + n_labels;
    let scaled = prescale(ex, input.weights)?;
    let lv = (params.label_weight / 2.0).sqrt();
    let mut aug = Vec::with_capacity(ex.h * ex.w * ca);
    for (px, &l) in scaled.chunks_exact(c0).zip(input.labels_in) {
        aug.extend_from_slice(px);
        aug.extend((0..n_labels).map(|k| if k == l as usize { lv } else { 0.0 }));
    }

    // Pyramids: steps from level l to l + 1, and each level's data.
    let (eys, exs) = (level_sizes(ex.h, levels), level_sizes(ex.w, levels));
    let (oys, oxs) = (level_sizes(oh, levels), level_sizes(ow, levels));
    let steps = |ys: &[usize], xs: &[usize]| -> Vec<Step> {
        (0..levels - 1)
            .map(|l| Step::new(ys[l], xs[l], ys[l + 1], xs[l + 1]))
            .collect()
    };
    let (ex_steps, out_steps) = (steps(&eys, &exs), steps(&oys, &oxs));
    let mut ex_levels = vec![ExLevel {
        h: ex.h,
        w: ex.w,
        aug,
        labels: input.labels_in.to_vec(),
        by_label: init::pixels_by_label(input.labels_in, n_labels),
    }];
    let mut out_labels = vec![input.labels_out.to_vec()];
    for (es, os) in ex_steps.iter().zip(&out_steps) {
        let prev = ex_levels.last().expect("level");
        let labels = es.down(&prev.labels, 1);
        let by_label = init::pixels_by_label(&labels, n_labels);
        let lo = os.down(out_labels.last().expect("level"), 1);
        if lo.iter().any(|&l| by_label[l as usize].is_empty()) {
            // A label vanished from the coarse exemplar; stop the pyramid here.
            break;
        }
        ex_levels.push(ExLevel {
            h: es.ch(),
            w: es.cw(),
            aug: es.down(&prev.aug, ca),
            labels,
            by_label,
        });
        out_labels.push(lo);
    }
    let levels = ex_levels.len();

    let total = (0..levels)
        .map(|l| level_iterations(params.iterations, l))
        .sum();
    let mut done = 0;
    let mut refs: Vec<u32> = Vec::new();
    for l in (0..levels).rev() {
        let el = &ex_levels[l];
        let lo = &out_labels[l];
        let (h, w) = (oys[l], oxs[l]);
        if refs.is_empty() {
            refs = match params.init {
                Init::Random => init::random_init(lo, &el.by_label, params.seed, 0x1A17),
                Init::Smart => {
                    let a = init::LabelMap::new(&el.labels, el.h, el.w);
                    let b = init::LabelMap::new(lo, h, w);
                    init::smart_init(&a, &b, p, params.seed)
                }
            };
        } else {
            refs = upsample_refs(&refs, &out_steps[l], &ex_steps[l], params.wrap);
        }
        crate::cancel::check()?;
        let solver = Level::new(el, lo, h, w, ca, c0, p, params, l)?;
        let iterations = level_iterations(params.iterations, l);
        for it in 0..iterations {
            crate::cancel::check()?;
            refs = solver.iterate(&refs, it)?;
            done += 1;
            if let Some(f) = progress {
                f(done, total);
            }
        }
        if l == 0 && params.composite > 0 {
            let c = if params.seam_channels == 0 {
                c0
            } else {
                params.seam_channels.min(c0)
            };
            let table = params.stand_in_weight.is_finite().then(|| {
                // Stand-ins match a pixel and its surroundings at the patch's scale.
                let desc = composite::descriptors(&el.aug, ca, c, el.h, el.w, p / 2);
                composite::StandIns::new(
                    &desc,
                    2 * c,
                    &el.labels,
                    n_labels,
                    composite::STAND_IN_BUDGET,
                )
            });
            let scene = composite::Scene {
                stand_ins: table.as_ref(),
                stand_in_weight: params.stand_in_weight,
                ex: &el.aug,
                stride: ca,
                c,
                eh: el.h,
                ew: el.w,
                labels_in: &el.labels,
                labels_out: lo,
                h,
                w,
            };
            composite::composite(&scene, &mut refs, params.composite, params.seed)?;
        }
    }
    Ok(Tbn { h: oh, w: ow, refs })
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::rng::Rng;

    fn naive_neighbourhood(
        refs: &[u32],
        (h, w): (usize, usize),
        (y, x): (usize, usize),
        p: usize,
        (eh, ew): (usize, usize),
        wrap: bool,
    ) -> Vec<Option<(usize, usize)>> {
        // Straight from Fig. 3.1: neighbour q = p0 + o refers to (ry, rx); the forward-shifted
        // reference is (ry − oy, rx − ox), wrapped or undefined outside the exemplar.
        let r = (p / 2) as i64;
        let mut out = Vec::new();
        for oy in -r..=r {
            for ox in -r..=r {
                let (qy, qx) = (y as i64 + oy, x as i64 + ox);
                if qy < 0 || qx < 0 || qy >= h as i64 || qx >= w as i64 {
                    out.push(None);
                    continue;
                }
                let e = refs[qy as usize * w + qx as usize] as usize;
                let (ry, rx) = ((e / ew) as i64 - oy, (e % ew) as i64 - ox);
                let inside = ry >= 0 && rx >= 0 && ry < eh as i64 && rx < ew as i64;
                out.push(if inside {
                    Some((ry as usize, rx as usize))
                } else if wrap {
                    Some((
                        ry.rem_euclid(eh as i64) as usize,
                        rx.rem_euclid(ew as i64) as usize,
                    ))
                } else {
                    None
                });
            }
        }
        out
    }

    #[test]
    fn forward_shift_matches_a_naive_reference() {
        let (h, w, eh, ew) = (9, 11, 7, 8);
        let mut rng = Rng::keyed(1, 1, 1);
        let refs: Vec<u32> = (0..h * w)
            .map(|_| rng.below((eh * ew) as u64) as u32)
            .collect();
        for wrap in [false, true] {
            for p in [1, 3, 5] {
                for y in 0..h {
                    for x in 0..w {
                        let got: Vec<Option<(usize, usize)>> =
                            forward_shifted(&refs, (h, w), (y, x), p, (eh, ew), wrap, false)
                                .into_iter()
                                .map(|e| (e != NONE).then(|| (e as usize / ew, e as usize % ew)))
                                .collect();
                        assert_eq!(
                            got,
                            naive_neighbourhood(&refs, (h, w), (y, x), p, (eh, ew), wrap)
                        );
                    }
                }
            }
        }
        // A coherent copy forward-shifts to the same reference from every neighbour.
        let block: Vec<u32> = (0..25)
            .map(|i| ((1 + i / 5) * ew + 1 + i % 5) as u32)
            .collect();
        let n = forward_shifted(&block, (5, 5), (2, 2), 3, (eh, ew), false, false);
        assert!(n.iter().all(|&e| e == block[12]));
        // Without wrap, a shift past the exemplar's edge is undefined; with wrap it comes round.
        assert_eq!(shift(0, -1, 0, eh, ew, false), NONE);
        assert_eq!(shift(0, -1, 0, eh, ew, true), ((eh - 1) * ew) as u32);
    }

    fn scene(h: usize, w: usize, phase: usize) -> (Vec<f32>, Vec<u32>) {
        // Two materials in stripes: label 0 a fine sine, label 1 a coarse one.
        let mut img = Vec::new();
        let mut lab = Vec::new();
        for y in 0..h {
            for x in 0..w {
                let l = u32::from(((x + y / 3 + phase) / 8) % 2 == 1);
                let (fy, fx) = (y as f32, x as f32);
                let v = if l == 0 {
                    0.3 + 0.2 * (fx * 0.9).sin() * (fy * 0.7).cos()
                } else {
                    0.7 + 0.2 * (fx * 0.3 + fy * 0.2).sin()
                };
                img.extend([v, 1.0 - v, 0.5 * v]);
                lab.push(l);
            }
        }
        (img, lab)
    }

    fn run(params: &TbnParams) -> (Tbn, Vec<u32>, Vec<u32>) {
        let (eh, ew, oh, ow) = (40, 48, 44, 52);
        let (img, la) = scene(eh, ew, 0);
        let (_, lb) = scene(oh, ow, 5);
        let input = TbnInput {
            exemplar: Image::new("exemplar", &img, eh, ew, 3).unwrap(),
            weights: None,
            labels_in: &la,
            labels_out: &lb,
            out_h: oh,
            out_w: ow,
        };
        (by_numbers(&input, params, None).unwrap(), la, lb)
    }

    #[test]
    fn every_pixel_comes_from_its_own_label() {
        for init in [Init::Smart, Init::Random] {
            for wrap in [false, true] {
                let params = TbnParams {
                    init,
                    wrap,
                    levels: Some(2),
                    ..TbnParams::default()
                };
                let (t, la, lb) = run(&params);
                assert!(t.refs.iter().zip(&lb).all(|(&e, &l)| la[e as usize] == l));
            }
        }
    }

    #[test]
    fn medoid_selection_keeps_labels_and_determinism() {
        let params = TbnParams {
            levels: Some(2),
            selection: Selection::Medoid,
            ..TbnParams::default()
        };
        let (t, la, lb) = run(&params);
        assert!(t.refs.iter().zip(&lb).all(|(&e, &l)| la[e as usize] == l));
        let one = rayon::ThreadPoolBuilder::new()
            .num_threads(1)
            .build()
            .unwrap();
        assert_eq!(one.install(|| run(&params).0.refs), t.refs);
        let avg = run(&TbnParams {
            selection: Selection::Average,
            ..params
        });
        assert_ne!(avg.0.refs, t.refs);
    }

    #[test]
    fn deterministic_across_threads_and_seeded() {
        let params = TbnParams {
            levels: Some(2),
            ..TbnParams::default()
        };
        let one = rayon::ThreadPoolBuilder::new()
            .num_threads(1)
            .build()
            .unwrap();
        let three = rayon::ThreadPoolBuilder::new()
            .num_threads(3)
            .build()
            .unwrap();
        let a = one.install(|| run(&params).0.refs);
        let b = three.install(|| run(&params).0.refs);
        assert_eq!(a, b);
        let c = run(&TbnParams { seed: 9, ..params }).0.refs;
        assert_ne!(a, c);
    }

    #[test]
    fn optimisation_makes_the_output_coherent() {
        // Coherence: the share of horizontal neighbours copied from horizontal neighbours
        // grows from a random start.
        let coherent = |refs: &[u32], w: usize, ew: u32| {
            refs.chunks_exact(w)
                .flat_map(|row| row.windows(2))
                .filter(|p| p[1] == p[0] + 1 && p[1] % ew != 0)
                .count()
        };
        let base = TbnParams {
            init: Init::Random,
            levels: Some(1),
            ..TbnParams::default()
        };
        let (t, _, _) = run(&base);
        let start = {
            let (_, la) = scene(40, 48, 0);
            let (_, lb) = scene(44, 52, 5);
            init::random_init(&lb, &init::pixels_by_label(&la, 2), 0, 0x1A17)
        };
        assert!(coherent(&t.refs, 52, 48) > 5 * coherent(&start, 52, 48).max(10));
    }

    #[test]
    fn simd_and_portable_paths_agree() {
        use crate::distance::FORCE_PORTABLE;
        use std::sync::atomic::Ordering;
        let params = TbnParams {
            levels: Some(2),
            ..TbnParams::default()
        };
        FORCE_PORTABLE.store(true, Ordering::Relaxed);
        let portable = run(&params).0.refs;
        FORCE_PORTABLE.store(false, Ordering::Relaxed);
        assert_eq!(portable, run(&params).0.refs);
    }

    #[test]
    fn bad_arguments_name_the_parameter() {
        let (img, la) = scene(20, 20, 0);
        let lb = vec![0u32; 400];
        let input = TbnInput {
            exemplar: Image::new("exemplar", &img, 20, 20, 3).unwrap(),
            weights: None,
            labels_in: &la,
            labels_out: &lb,
            out_h: 20,
            out_w: 20,
        };
        let err = |p: TbnParams, i: TbnInput<'_>| match by_numbers(&i, &p, None) {
            Err(crate::Error::InvalidArgument { name, .. }) => name,
            other => panic!("{other:?}"),
        };
        let d = TbnParams::default();
        assert_eq!(
            err(
                TbnParams {
                    patch_size: 4,
                    ..d.clone()
                },
                input
            ),
            "patch_size"
        );
        assert_eq!(err(TbnParams { k: 0, ..d.clone() }, input), "k");
        assert_eq!(
            err(
                TbnParams {
                    patch_size: 21,
                    ..d.clone()
                },
                input
            ),
            "exemplar"
        );
        let bad = vec![2u32; 400];
        assert_eq!(
            err(
                d.clone(),
                TbnInput {
                    labels_out: &bad,
                    ..input
                }
            ),
            "labels_out"
        );
        assert_eq!(
            err(
                d,
                TbnInput {
                    labels_in: &la[..399],
                    ..input
                }
            ),
            "labels_in"
        );
    }
}
