//! Boundary-patch shape synthesis: Rosenberger, Cohen-Or, Lischinski 2009, "Layered shape
//! synthesis: automatic generation of control maps for non-stationary textures", as
//! described in §3.6 of the bark thesis (paper 001).
//!
//! A shape (a binary map) is synthesised like a texture (Kwatra et al. 2005), but only its
//! boundaries are compared: starting from random noise with the exemplar's area fraction, on
//! an image pyramid from coarse to fine, each iteration matches every boundary patch of the
//! output to an exemplar boundary patch under a (capped) quota ([`matching`]), lets the matched patches
//! vote for each pixel and re-labels the pixels under an area constraint ([`adjust`]). A level
//! ends after `iterations` iterations or as soon as the shape stops changing.
//!
//! Label maps with `k` labels are made in one of two ways ([`Method`]):
//! - *layered* (the paper's layer maps, §3.6.4): labels are nested layers in a given order;
//!   each layer is a binary shape synthesised inside the previous layer, whose mask is first
//!   shrunk where the previous layer's matched exemplar patches show no next layer;
//! - *joint*: all labels at once. Boundary pixels are grouped by the pair of labels that
//!   meet there; each group is matched against the exemplar's boundary patches of the same
//!   pair under its own quota, the votes count per label, and every label keeps its area.
//!
//! [`similarity`] is the shape distance of Eq. 3.7–3.9.

pub mod adjust;
pub mod matching;
pub mod patches;

use std::collections::{BTreeMap, HashMap};

use rayon::prelude::*;

use crate::error::{invalid, Error, Result};
use crate::rng::{mix64, Rng};
use adjust::{decide, falloff, votes, Overlay};
use matching::{
    exact_candidates, match_all, propagate, quotas, Index, Lookup, EXACT_WORK, K, NONE, QUOTA_SLACK,
};
use patches::{boundary, other_label, Geometry, Patch};

pub use patches::MAX_PATCH;

/// The largest number of labels of a label map.
pub const MAX_LABELS: usize = 64;

/// [`layer_order`] searches all orders of up to this many labels.
pub const MAX_ORDER_SEARCH: usize = 7;

/// The most pyramid levels chosen automatically.
const MAX_AUTO_LEVELS: usize = 6;

/// Automatic pyramids stop at the level where the exemplar and output are this many patches
/// wide: with one, a patch covers a whole blob of the exemplar at the coarsest level (with
/// three, outputs' blobs came out about half the exemplar's chord length).
const AUTO_MIN_PATCHES: usize = 1;

/// A pixel near a layer boundary leaves the next layer's mask when less than this share of
/// the votes of the previous layer's matched exemplar patches shows the next layer there.
const SHRINK_SHARE: f32 = 0.1;

/// Which 90° turns of the exemplar's boundary patches may match (Eq. 3.7).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Rotations {
    /// The patches as they are: directions are kept (e.g. vertical bark furrows).
    None,
    /// The patches and their half-turns (0° and 180°): a vertical axis stays vertical.
    Half,
    /// All four 90° turns (the paper).
    All,
}

impl Rotations {
    /// The allowed turns, in quarter turns.
    #[must_use]
    pub fn turns(self) -> &'static [u8] {
        match self {
            Self::None => &[0],
            Self::Half => &[0, 2],
            Self::All => &[0, 1, 2, 3],
        }
    }

    /// From the number of allowed turns: 1, 2 or 4; errors name `rotations`.
    pub fn from_count(n: usize) -> Result<Self> {
        match n {
            1 => Ok(Self::None),
            2 => Ok(Self::Half),
            4 => Ok(Self::All),
            _ => Err(invalid(
                "rotations",
                format!("expected 1, 2 or 4 turns, got {n}"),
            )),
        }
    }
}

/// How a label map with more than two labels is synthesised.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Method {
    /// Nested binary layers, one after the other (the paper's layer maps).
    Layered,
    /// All labels optimised together, one boundary-patch set per pair of labels.
    Joint,
}

/// Parameters of the shape synthesisers. Validated before any work starts.
#[derive(Clone, Debug)]
pub struct ShapeParams {
    /// Side of the square boundary patches; odd, at most [`MAX_PATCH`]. Default 11.
    pub patch_size: usize,
    /// Pyramid levels; 0 (the default) picks as many as keep the coarsest exemplar and output
    /// at least one patch wide (three for [`Method::Layered`]; at most 6), so that at the
    /// coarsest level a patch covers a whole blob and the random start grows blobs of the
    /// exemplar's scale.
    pub levels: usize,
    /// Matching + adjustment iterations per level (fewer if the shape stops changing).
    /// Default 5.
    pub iterations: usize,
    /// The 90° turns under which boundary patches are compared (Eq. 3.7). Default all four.
    pub rotations: Rotations,
    /// The output wraps around (toroidal), so it tiles seamlessly. Default false.
    pub tileable: bool,
    /// Seed of every random choice (initialisation, quota draws, tie-breaks).
    pub seed: u64,
}

impl Default for ShapeParams {
    fn default() -> Self {
        Self {
            patch_size: 11,
            levels: 0,
            iterations: 5,
            rotations: Rotations::All,
            tileable: false,
            seed: 0,
        }
    }
}

/// A label map: `h × w` labels, row-major.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct LabelMap {
    /// The labels.
    pub data: Vec<u8>,
    /// Height.
    pub h: usize,
    /// Width.
    pub w: usize,
}

impl LabelMap {
    /// A map checked to hold `h × w` labels below `k`; errors name `name`.
    pub fn new(name: &'static str, data: Vec<u8>, h: usize, w: usize, k: usize) -> Result<Self> {
        if data.len() != h * w || h == 0 || w == 0 {
            return Err(invalid(
                name,
                format!("expected {h}×{w} = {} labels, got {}", h * w, data.len()),
            ));
        }
        if let Some(&l) = data.iter().find(|&&l| l as usize >= k) {
            return Err(invalid(
                name,
                format!("expected labels in 0..{k}, found {l}"),
            ));
        }
        Ok(Self { data, h, w })
    }

    fn count(&self, l: u8) -> usize {
        self.data.iter().map(|&v| usize::from(v == l)).sum()
    }
}

/// A progress callback: `(done, total)` iterations; returning `false` cancels the run.
pub type Progress<'a> = Option<&'a (dyn Fn(usize, usize) -> bool + Sync)>;

fn check_patch(p: usize) -> Result<()> {
    if p == 0 || p % 2 == 0 || p > MAX_PATCH {
        return Err(invalid(
            "patch_size",
            format!("expected an odd size in 1..={MAX_PATCH}, got {p}"),
        ));
    }
    Ok(())
}

/// Checks `params` against an exemplar (`name`) and output size; returns the level count.
fn check(
    params: &ShapeParams,
    name: &'static str,
    ex: &LabelMap,
    h: usize,
    w: usize,
    min_patches: usize,
) -> Result<usize> {
    let p = params.patch_size;
    check_patch(p)?;
    if params.iterations == 0 {
        return Err(invalid(
            "iterations",
            "expected at least 1 iteration, got 0",
        ));
    }
    if ex.h < p || ex.w < p {
        return Err(invalid(
            name,
            format!(
                "expected at least {p}×{p} pixels (patch_size), got {}×{}",
                ex.h, ex.w
            ),
        ));
    }
    if h < p || w < p {
        return Err(invalid(
            "size",
            format!("expected at least {p}×{p} (patch_size), got {h}×{w}"),
        ));
    }
    let m = h.min(w).min(ex.h).min(ex.w);
    if params.levels == 0 {
        Ok(1 + (1..MAX_AUTO_LEVELS)
            .take_while(|&l| (m >> l) >= min_patches * p)
            .count())
    } else if (m >> (params.levels - 1)) < p {
        Err(invalid(
            "levels",
            format!(
                "{} levels shrink the smallest side ({m} px) below patch_size {p}",
                params.levels
            ),
        ))
    } else {
        Ok(params.levels)
    }
}

fn ceil_shift(n: usize, l: usize) -> usize {
    (n + (1 << l) - 1) >> l
}

/// Halves a label map: each pixel takes the most common label of its 2×2 block (the
/// top-left one on a tie).
fn down(m: &LabelMap) -> LabelMap {
    let (h, w) = (m.h.div_ceil(2), m.w.div_ceil(2));
    let mut data = vec![0u8; h * w];
    for y in 0..h {
        for x in 0..w {
            let mut seen = [(0u8, 0u8); 4];
            let mut n = 0;
            for (dy, dx) in [(0, 0), (0, 1), (1, 0), (1, 1)] {
                let (yy, xx) = (2 * y + dy, 2 * x + dx);
                if yy >= m.h || xx >= m.w {
                    continue;
                }
                let l = m.data[yy * m.w + xx];
                if let Some(s) = seen[..n].iter_mut().find(|s| s.0 == l) {
                    s.1 += 1;
                } else {
                    seen[n] = (l, 1);
                    n += 1;
                }
            }
            let mut best = seen[0];
            for s in &seen[1..n] {
                if s.1 > best.1 {
                    best = *s;
                }
            }
            data[y * w + x] = best.0;
        }
    }
    LabelMap { data, h, w }
}

/// Nearest-neighbour upsampling to `h × w`.
fn up(m: &LabelMap, h: usize, w: usize) -> LabelMap {
    let mut data = vec![0u8; h * w];
    for y in 0..h {
        let sy = y * m.h / h;
        for x in 0..w {
            data[y * w + x] = m.data[sy * m.w + x * m.w / w];
        }
    }
    LabelMap { data, h, w }
}

/// Label counts for `n` pixels with the given fractions, summing to `n` exactly.
fn targets_for(fracs: &[f64], n: usize) -> Vec<usize> {
    let mut cum = 0.0;
    let mut prev = 0usize;
    fracs
        .iter()
        .enumerate()
        .map(|(i, &f)| {
            cum += f;
            let next = if i + 1 == fracs.len() {
                n
            } else {
                ((cum * n as f64).round() as usize).min(n)
            };
            let t = next.saturating_sub(prev);
            prev = prev.max(next);
            t
        })
        .collect()
}

fn pair_key(a: u8, b: u8) -> u16 {
    let (a, b) = if a <= b { (a, b) } else { (b, a) };
    u16::from(a) * MAX_LABELS as u16 + u16::from(b)
}

/// The exemplar boundary patches of one label pair (or of all pairs).
struct Group {
    index: Index,
    /// Copies of each unique patch in the exemplar.
    mult: Vec<u32>,
    /// One exemplar pixel showing each unique patch.
    rep: Vec<u32>,
    lookup: Lookup,
    cache: HashMap<Patch, Vec<(u32, u32)>>,
}

impl Group {
    /// `items` sorted by patch: `(patch, exemplar pixel)` of an `eh × ew` exemplar.
    fn new(
        g: &Geometry,
        items: &[(Patch, u32)],
        rotations: Rotations,
        key_label: u8,
        (eh, ew): (usize, usize),
    ) -> Self {
        let mut unique = Vec::new();
        let mut mult = Vec::new();
        let mut rep = Vec::new();
        let mut pixel_ids = Vec::with_capacity(items.len());
        for (i, it) in items.iter().enumerate() {
            if i > 0 && items[i - 1].0 == it.0 {
                *mult.last_mut().expect("a previous patch") += 1;
            } else {
                unique.push(it.0);
                mult.push(1);
                rep.push(it.1);
            }
            pixel_ids.push((it.1, unique.len() as u32 - 1));
        }
        let index = Index::new(g, &unique, rotations, key_label);
        let lookup = Lookup::new(&index, &pixel_ids, eh, ew);
        Self {
            index,
            mult,
            rep,
            lookup,
            cache: HashMap::new(),
        }
    }
}

/// The last matching of a run, at full resolution: each matched output boundary pixel with
/// the exemplar pixel and rotation of its match.
#[derive(Default)]
struct LastMatch {
    centres: Vec<u32>,
    src: Vec<(u32, u8)>,
    dists: Vec<u32>,
}

struct Engine<'a> {
    g: Geometry,
    k: usize,
    params: &'a ShapeParams,
    levels: usize,
    progress: Progress<'a>,
    done: usize,
    total: usize,
}

impl<'a> Engine<'a> {
    /// An engine for `k` labels whose progress counts `runs` optimisations of `levels`
    /// levels each.
    fn new(
        k: usize,
        params: &'a ShapeParams,
        levels: usize,
        progress: Progress<'a>,
        runs: usize,
    ) -> Self {
        Engine {
            g: Geometry::new(params.patch_size, k),
            k,
            params,
            levels,
            progress,
            done: 0,
            total: runs * levels * params.iterations,
        }
    }

    fn tick(&mut self, n: usize) -> Result<()> {
        self.done += n;
        if let Some(f) = self.progress {
            if !f(self.done.min(self.total), self.total) {
                return Err(Error::Internal("cancelled by the progress callback".into()));
            }
        }
        Ok(())
    }

    /// The exemplar's boundary patches grouped by label pair, and (for more than two labels)
    /// all of them sorted by patch, for a group of output pairs the exemplar lacks.
    fn groups(&self, ex: &LabelMap) -> (BTreeMap<u16, Group>, Vec<(Patch, u32)>) {
        let g = &self.g;
        let r = g.p / 2;
        let all = boundary(&ex.data, ex.h, ex.w, false);
        // Patches that reach past the exemplar border repeat its edge pixels, which real
        // boundaries never do; leave them out when the exemplar is large enough.
        let inner: Vec<u32> = if ex.h >= 3 * g.p && ex.w >= 3 * g.p {
            all.iter()
                .copied()
                .filter(|&c| {
                    let (y, x) = (c as usize / ex.w, c as usize % ex.w);
                    y >= r && x >= r && y + r < ex.h && x + r < ex.w
                })
                .collect()
        } else {
            Vec::new()
        };
        let b = if inner.is_empty() { all } else { inner };
        let mut items: Vec<(u16, Patch, u32)> = b
            .par_iter()
            .map(|&c| {
                let (y, x) = (c as usize / ex.w, c as usize % ex.w);
                let o = other_label(&ex.data, ex.h, ex.w, y, x, false);
                (
                    pair_key(ex.data[c as usize], o),
                    g.extract(&ex.data, ex.h, ex.w, y, x, false),
                    c,
                )
            })
            .collect();
        items.par_sort_unstable();
        let mut groups = BTreeMap::new();
        let mut i = 0;
        while i < items.len() {
            let key = items[i].0;
            let j = i + items[i..].partition_point(|it| it.0 == key);
            let group: Vec<(Patch, u32)> = items[i..j].iter().map(|it| (it.1, it.2)).collect();
            let low = (key / MAX_LABELS as u16) as u8;
            groups.insert(
                key,
                Group::new(g, &group, self.params.rotations, low, (ex.h, ex.w)),
            );
            i = j;
        }
        let mut all: Vec<(Patch, u32)> = Vec::new();
        if self.k > 2 {
            all = items.iter().map(|it| (it.1, it.2)).collect();
            all.par_sort_unstable();
        }
        (groups, all)
    }

    fn random_init(
        &self,
        h: usize,
        w: usize,
        allowed: Option<&[bool]>,
        targets: &[usize],
        stream: u64,
    ) -> LabelMap {
        let mut idx: Vec<u32> = (0..(h * w) as u32)
            .filter(|&i| allowed.is_none_or(|a| a[i as usize]))
            .collect();
        let mut rng = Rng::keyed(self.params.seed, stream, 0x1417);
        for i in (1..idx.len()).rev() {
            let j = rng.below(i as u64 + 1) as usize;
            idx.swap(i, j);
        }
        let mut data = vec![0u8; h * w];
        let mut at = 0;
        for (l, &t) in targets.iter().enumerate() {
            for &i in &idx[at..(at + t).min(idx.len())] {
                data[i as usize] = l as u8;
            }
            at += t;
        }
        LabelMap { data, h, w }
    }

    /// A `k`-label map of `h × w` like `ex`, with label fractions `fracs` of the allowed
    /// pixels; pixels outside `allowed` stay 0. `stream` keys this run's random numbers.
    fn optimise(
        &mut self,
        ex: &LabelMap,
        h: usize,
        w: usize,
        allowed: Option<&[bool]>,
        fracs: &[f64],
        stream: u64,
    ) -> Result<(LabelMap, LastMatch)> {
        let (k, wrap, p) = (self.k, self.params.tileable, self.g.p);
        let fall = falloff(p);
        let mut exs = vec![ex.clone()];
        for l in 1..self.levels {
            exs.push(down(&exs[l - 1]));
        }
        let mut cur: Option<LabelMap> = None;
        let mut last = LastMatch::default();
        let mut field: Vec<(u32, u8)> = Vec::new();
        for l in (0..self.levels).rev() {
            let (hl, wl) = (ceil_shift(h, l), ceil_shift(w, l));
            let al: Option<Vec<bool>> = allowed.map(|a| {
                let half = (1usize << l) / 2;
                (0..hl * wl)
                    .map(|i| {
                        let (y, x) = (
                            (((i / wl) << l) + half).min(h - 1),
                            (((i % wl) << l) + half).min(w - 1),
                        );
                        a[y * w + x]
                    })
                    .collect()
            });
            let al = al.as_deref();
            let n_ok = al.map_or(hl * wl, |a| a.iter().filter(|&&v| v).count());
            let targets = targets_for(fracs, n_ok);
            let level_key = mix64(stream.wrapping_mul(64) + l as u64);
            let mut map = match cur.take() {
                None => self.random_init(hl, wl, al, &targets, level_key),
                Some(m) => {
                    let mut m = up(&m, hl, wl);
                    if let Some(a) = al {
                        for (v, &ok) in m.data.iter_mut().zip(a) {
                            if !ok {
                                *v = 0;
                            }
                        }
                    }
                    m
                }
            };
            let (mut groups, all) = self.groups(&exs[l]);
            // Built on first use only: most iterations have no pair the exemplar lacks.
            let mut global: Option<Group> = None;
            // The previous level's matches, scaled up, seed this level's search.
            field = if field.is_empty() {
                vec![(NONE, 0u8); hl * wl]
            } else {
                let (ch, cw) = (ceil_shift(h, l + 1), ceil_shift(w, l + 1));
                let (eh, ew) = (exs[l].h, exs[l].w);
                let cew = exs[l + 1].w;
                (0..hl * wl)
                    .map(|i| {
                        let (y, x) = (i / wl, i % wl);
                        let (p, r) = field[(y / 2).min(ch - 1) * cw + (x / 2).min(cw - 1)];
                        if p == NONE {
                            return (NONE, 0);
                        }
                        let (py, px) = (p as usize / cew, p as usize % cew);
                        (
                            ((2 * py + y % 2).min(eh - 1) * ew + (2 * px + x % 2).min(ew - 1))
                                as u32,
                            r,
                        )
                    })
                    .collect()
            };
            let mut its = 0;
            for it in 0..self.params.iterations {
                crate::cancel::check()?;
                let key = mix64(self.params.seed ^ mix64(level_key ^ (it as u64) << 20));
                let centres: Vec<u32> = boundary(&map.data, hl, wl, wrap)
                    .into_iter()
                    .filter(|&c| al.is_none_or(|a| a[c as usize]))
                    .collect();
                if centres.is_empty() || groups.is_empty() {
                    break;
                }
                let qs: Vec<(u16, Patch)> = centres
                    .par_iter()
                    .map(|&c| {
                        let (y, x) = (c as usize / wl, c as usize % wl);
                        let o = other_label(&map.data, hl, wl, y, x, wrap);
                        (
                            pair_key(map.data[c as usize], o),
                            self.g.extract(&map.data, hl, wl, y, x, wrap),
                        )
                    })
                    .collect();
                let mut buckets: BTreeMap<u16, Vec<usize>> = BTreeMap::new();
                for (i, q) in qs.iter().enumerate() {
                    let b = if groups.contains_key(&q.0) {
                        q.0
                    } else {
                        u16::MAX
                    };
                    buckets.entry(b).or_default().push(i);
                }
                let n = centres.len();
                let mut src = vec![(NONE, 0u8); n];
                let mut matched = vec![Patch::default(); n];
                let mut dists = vec![0u32; n];
                for (b, members) in &buckets {
                    crate::cancel::check()?;
                    if *b == u16::MAX && global.is_none() && !all.is_empty() {
                        let dims = (exs[l].h, exs[l].w);
                        global = Some(Group::new(&self.g, &all, self.params.rotations, 0, dims));
                    }
                    let Some(grp) = (if *b == u16::MAX {
                        global.as_mut()
                    } else {
                        groups.get_mut(b)
                    }) else {
                        continue;
                    };
                    let queries: Vec<Patch> = members.iter().map(|&i| qs[i].1).collect();
                    let quota = quotas(queries.len(), &grp.mult, QUOTA_SLACK, key ^ u64::from(*b));
                    let first = if queries.len() * grp.index.len() <= EXACT_WORK {
                        exact_candidates(&self.g, &grp.index, &queries, K, &mut grp.cache)
                    } else {
                        let cs: Vec<u32> = members.iter().map(|&i| centres[i]).collect();
                        let passes = if it == 0 { 3 } else { 2 };
                        propagate(
                            &grp.index,
                            &grp.lookup,
                            &grp.rep,
                            &queries,
                            &cs,
                            (hl, wl, wrap),
                            &mut field,
                            passes,
                            K,
                            key ^ u64::from(*b),
                        )
                    };
                    let m = match_all(
                        &self.g,
                        &grp.index,
                        &queries,
                        quota,
                        K,
                        &first,
                        key ^ u64::from(*b),
                    );
                    for (j, &i) in members.iter().enumerate() {
                        let (e, d) = m[j];
                        if e != NONE {
                            let e = e as usize;
                            matched[i] = grp.index.patches[e];
                            dists[i] = d;
                            src[i] = (grp.rep[grp.index.ids[e] as usize], grp.index.rots[e]);
                        }
                    }
                }
                crate::cancel::check()?;
                let keep: Vec<usize> = (0..n).filter(|&i| src[i].0 != NONE).collect();
                for &i in &keep {
                    field[centres[i] as usize] = src[i];
                }
                let centres: Vec<u32> = keep.iter().map(|&i| centres[i]).collect();
                let matched: Vec<Patch> = keep.iter().map(|&i| matched[i]).collect();
                let dists: Vec<u32> = keep.iter().map(|&i| dists[i]).collect();
                let src: Vec<(u32, u8)> = keep.iter().map(|&i| src[i]).collect();
                let ov = Overlay {
                    centres: &centres,
                    patches: &matched,
                    dists: &dists,
                };
                let rows = votes(&self.g, &ov, hl, wl, k, wrap, &fall);
                let (new, changed) = decide(&map.data, rows, al, k, &targets, key);
                map.data = new;
                its += 1;
                self.tick(1)?;
                if l == 0 {
                    last = LastMatch {
                        centres,
                        src,
                        dists,
                    };
                }
                if changed == 0 {
                    break;
                }
            }
            if its < self.params.iterations {
                self.tick(self.params.iterations - its)?;
            }
            cur = Some(map);
        }
        Ok((cur.expect("at least one level"), last))
    }

    /// Nested binary layers (§3.6.4): layer `i` holds the labels `order[i..]`.
    fn layered(
        &mut self,
        ex: &LabelMap,
        k: usize,
        h: usize,
        w: usize,
        order: &[u8],
    ) -> Result<LabelMap> {
        let mut rank = [0u8; MAX_LABELS];
        for (i, &l) in order.iter().enumerate() {
            rank[l as usize] = i as u8;
        }
        let layer = |i: usize| LabelMap {
            data: ex
                .data
                .iter()
                .map(|&l| u8::from(rank[l as usize] as usize >= i))
                .collect(),
            h: ex.h,
            w: ex.w,
        };
        let n_ex = (ex.h * ex.w) as f64;
        let mut out_rank = vec![0u8; h * w];
        let mut allowed: Option<Vec<bool>> = None;
        for i in 1..k {
            let exi = layer(i);
            let f_abs = exi.count(1) as f64 / n_ex;
            let n_ok = allowed
                .as_ref()
                .map_or(h * w, |a| a.iter().filter(|&&v| v).count());
            if n_ok == 0 {
                break;
            }
            let f = (f_abs * (h * w) as f64 / n_ok as f64).min(1.0);
            let (oi, last) =
                self.optimise(&exi, h, w, allowed.as_deref(), &[1.0 - f, f], i as u64)?;
            for (o, &v) in out_rank.iter_mut().zip(&oi.data) {
                if v == 1 {
                    *o = i as u8;
                }
            }
            if i + 1 == k {
                break;
            }
            // The next layer's mask: this layer, less the pixels near its boundary where the
            // matched exemplar patches show no next layer.
            let next = layer(i + 1);
            let patches: Vec<Patch> = last
                .src
                .iter()
                .map(|&(pix, rot)| {
                    let mut q = self.g.extract(
                        &next.data,
                        next.h,
                        next.w,
                        pix as usize / next.w,
                        pix as usize % next.w,
                        false,
                    );
                    for _ in 0..rot {
                        q = self.g.rotate(&q);
                    }
                    q
                })
                .collect();
            let ov = Overlay {
                centres: &last.centres,
                patches: &patches,
                dists: &last.dists,
            };
            let rows = votes(
                &self.g,
                &ov,
                h,
                w,
                2,
                self.params.tileable,
                &falloff(self.g.p),
            );
            let mut mask: Vec<bool> = oi.data.iter().map(|&v| v == 1).collect();
            let mut share1 = vec![0f32; h * w];
            for row in &rows {
                for &(px, l, s, _) in &row.entries {
                    if l == 1 {
                        share1[px as usize] = s;
                    }
                }
            }
            let voted = rows.iter().flat_map(|r| r.voted.iter().copied());
            for ((m, v), s) in mask.iter_mut().zip(voted).zip(&share1) {
                if v && *s < SHRINK_SHARE {
                    *m = false;
                }
            }
            let need = (next.count(1) as f64 / n_ex * (h * w) as f64).ceil() as usize;
            if mask.iter().filter(|&&m| m).count() < need {
                mask = oi.data.iter().map(|&v| v == 1).collect();
            }
            allowed = Some(mask);
        }
        Ok(LabelMap {
            data: out_rank.into_iter().map(|r| order[r as usize]).collect(),
            h,
            w,
        })
    }
}

/// A binary shape (`shape`: 0/1) of `h × w` pixels synthesised like `shape`; pixels outside
/// `mask` stay 0 and the shape's area is the exemplar's fraction of the masked pixels.
pub fn synthesize(
    shape: &LabelMap,
    h: usize,
    w: usize,
    mask: Option<&[bool]>,
    params: &ShapeParams,
    progress: Progress<'_>,
) -> Result<LabelMap> {
    let levels = check(params, "shape", shape, h, w, AUTO_MIN_PATCHES)?;
    if let Some(&l) = shape.data.iter().find(|&&l| l > 1) {
        return Err(invalid("shape", format!("expected 0/1 values, found {l}")));
    }
    let fg = shape.count(1);
    if fg == 0 || fg == shape.data.len() {
        return Err(invalid(
            "shape",
            "expected both 0 and 1 pixels, the shape is empty or full",
        ));
    }
    if let Some(m) = mask {
        if m.len() != h * w {
            return Err(invalid(
                "mask",
                format!("expected {h}×{w} values, got {}", m.len()),
            ));
        }
        if !m.iter().any(|&v| v) {
            return Err(invalid("mask", "expected at least one allowed pixel"));
        }
    }
    let f = fg as f64 / shape.data.len() as f64;
    let mut e = Engine::new(2, params, levels, progress, 1);
    Ok(e.optimise(shape, h, w, mask, &[1.0 - f, f], 0)?.0)
}

/// The inferred layer order of a map with `k` labels, bottom first. In a map of nested layers
/// boundaries run between consecutive layers, so the order is the one whose boundaries
/// between non-consecutive layers are shortest (searched over all orders for up to
/// [`MAX_ORDER_SEARCH`] labels); its bottom is the larger end. Beyond that, and on ties,
/// labels go by decreasing area (the largest label is the ground the others lie on).
#[must_use]
pub fn layer_order(labels: &LabelMap, k: usize) -> Vec<u8> {
    let (h, w) = (labels.h, labels.w);
    let mut counts = vec![0usize; k];
    let mut adj = vec![0usize; k * k];
    for y in 0..h {
        for x in 0..w {
            let l = labels.data[y * w + x] as usize;
            counts[l] += 1;
            if x + 1 < w {
                let m = labels.data[y * w + x + 1] as usize;
                adj[l * k + m] += 1;
                adj[m * k + l] += 1;
            }
            if y + 1 < h {
                let m = labels.data[(y + 1) * w + x] as usize;
                adj[l * k + m] += 1;
                adj[m * k + l] += 1;
            }
        }
    }
    let mut order: Vec<u8> = (0..k as u8).collect();
    order.sort_by_key(|&l| (std::cmp::Reverse(counts[l as usize]), l));
    if k > MAX_ORDER_SEARCH {
        return order;
    }
    let cost = |o: &[u8]| -> usize {
        let mut c = 0;
        for i in 0..o.len() {
            for j in i + 2..o.len() {
                c += adj[o[i] as usize * k + o[j] as usize];
            }
        }
        c
    };
    // Heap's algorithm over the area order, keeping the first cheapest (so ties stay by area).
    let mut best = (cost(&order), order.clone());
    let mut p = order.clone();
    let mut c = vec![0usize; k];
    let mut i = 1;
    while i < k {
        if c[i] < i {
            if i % 2 == 0 {
                p.swap(0, i);
            } else {
                p.swap(c[i], i);
            }
            let oriented = if counts[p[0] as usize] >= counts[p[k - 1] as usize] {
                p.clone()
            } else {
                p.iter().rev().copied().collect()
            };
            let cc = cost(&oriented);
            if cc < best.0 {
                best = (cc, oriented);
            }
            c[i] += 1;
            i = 1;
        } else {
            c[i] = 0;
            i += 1;
        }
    }
    best.1
}

/// A `k`-label map of `h × w` pixels synthesised like `labels` (labels `0..k`, each present).
/// `order` (layered only) lists the labels bottom layer first; `None` infers it with
/// [`layer_order`].
pub fn synthesize_labels(
    labels: &LabelMap,
    k: usize,
    h: usize,
    w: usize,
    method: Method,
    order: Option<&[u8]>,
    params: &ShapeParams,
    progress: Progress<'_>,
) -> Result<LabelMap> {
    // Deeper pyramids make the layered method's nested masks coarse and cost it Eq. 3.9
    // (eucalyptus: 3.29 at 5 levels against 2.10 at 3), so it keeps three patches.
    let min_patches = if method == Method::Layered {
        3
    } else {
        AUTO_MIN_PATCHES
    };
    let levels = check(params, "labels", labels, h, w, min_patches)?;
    if !(2..=MAX_LABELS).contains(&k) {
        return Err(invalid(
            "labels",
            format!("expected 2..={MAX_LABELS} labels, got {k}"),
        ));
    }
    let mut counts = vec![0usize; k];
    for &l in &labels.data {
        if l as usize >= k {
            return Err(invalid(
                "labels",
                format!("expected labels in 0..{k}, found {l}"),
            ));
        }
        counts[l as usize] += 1;
    }
    if let Some(l) = counts.iter().position(|&c| c == 0) {
        return Err(invalid(
            "labels",
            format!("label {l} of 0..{k} does not occur"),
        ));
    }
    let order: Vec<u8> = match order {
        Some(o) => {
            let mut seen = vec![false; k];
            for &l in o {
                if l as usize >= k || seen[l as usize] {
                    return Err(invalid(
                        "order",
                        format!("expected a permutation of the {k} labels, got {o:?}"),
                    ));
                }
                seen[l as usize] = true;
            }
            if o.len() != k {
                return Err(invalid(
                    "order",
                    format!("expected a permutation of the {k} labels, got {o:?}"),
                ));
            }
            o.to_vec()
        }
        None => layer_order(labels, k),
    };
    let n = labels.data.len() as f64;
    match method {
        Method::Layered => {
            let mut e = Engine::new(2, params, levels, progress, k - 1);
            e.layered(labels, k, h, w, &order)
        }
        Method::Joint => {
            let fracs: Vec<f64> = counts.iter().map(|&c| c as f64 / n).collect();
            let mut e = Engine::new(k, params, levels, progress, 1);
            Ok(e.optimise(labels, h, w, None, &fracs, 0)?.0)
        }
    }
}

/// The shape distance of Eq. 3.9 between two label maps (binary shapes or label maps with
/// up to [`MAX_LABELS`] labels, of any sizes): over the boundary pixels of both, the mean
/// distance (Eq. 3.7, differing pixels of `patch_size²`, the minimum over the four rotations
/// of the other map's patch with `rotations`) to the nearest boundary patch of the other map
/// (Eq. 3.8). The boundary sets belong to different maps, so `|B1 ∪ B2| = |B1| + |B2|`.
/// Patches reaching past a border repeat the border pixels. 0 when neither map has a
/// boundary, infinite when only one has. Lower is better.
pub fn similarity(
    a: &LabelMap,
    b: &LabelMap,
    patch_size: usize,
    rotations: Rotations,
) -> Result<f64> {
    check_patch(patch_size)?;
    let k = a.data.iter().chain(&b.data).copied().max().unwrap_or(0) as usize + 1;
    if k > MAX_LABELS {
        return Err(invalid(
            "a",
            format!("expected labels below {MAX_LABELS}, found {}", k - 1),
        ));
    }
    let g = Geometry::new(patch_size, k);
    let ba = boundary(&a.data, a.h, a.w, false);
    let bb = boundary(&b.data, b.h, b.w, false);
    if ba.is_empty() && bb.is_empty() {
        return Ok(0.0);
    }
    if ba.is_empty() || bb.is_empty() {
        return Ok(f64::INFINITY);
    }
    let pa: Vec<Patch> = ba
        .par_iter()
        .map(|&c| g.extract(&a.data, a.h, a.w, c as usize / a.w, c as usize % a.w, false))
        .collect();
    let pb: Vec<Patch> = bb
        .par_iter()
        .map(|&c| g.extract(&b.data, b.h, b.w, c as usize / b.w, c as usize % b.w, false))
        .collect();
    let sum = one_way(&g, &pa, &pb, rotations) + one_way(&g, &pb, &pa, rotations);
    Ok(sum as f64 / (pa.len() + pb.len()) as f64)
}

/// `Σ_{x ∈ from} D(x, to)` (Eq. 3.8), duplicates searched once.
fn one_way(g: &Geometry, from: &[Patch], to: &[Patch], rotations: Rotations) -> u64 {
    let mut to_u = to.to_vec();
    to_u.par_sort_unstable();
    to_u.dedup();
    // Key on the label most boundary patches of `to` show at their centre.
    let mut counts = [0usize; MAX_LABELS];
    let centre = g.p * g.p / 2;
    for t in &to_u {
        counts[g.label_at(t, centre) as usize] += 1;
    }
    let key = (0..MAX_LABELS)
        .max_by_key(|&l| (counts[l], std::cmp::Reverse(l)))
        .unwrap_or(0) as u8;
    let index = Index::new(g, &to_u, rotations, key);
    let mut q: Vec<Patch> = from.to_vec();
    q.par_sort_unstable();
    let mut runs: Vec<(Patch, u64)> = Vec::new();
    for p in q {
        match runs.last_mut() {
            Some(r) if r.0 == p => r.1 += 1,
            _ => runs.push((p, 1)),
        }
    }
    runs.par_iter()
        .map(|(p, n)| u64::from(index.knn(g, p, 1)[0].0) * n)
        .sum()
}

#[cfg(test)]
mod tests {
    use super::*;

    fn blobs(h: usize, w: usize, seed: u64, k: u8) -> LabelMap {
        // Discs of random labels on label 0.
        let mut r = Rng::keyed(seed, 5, 5);
        let mut data = vec![0u8; h * w];
        for _ in 0..(h * w / 150) {
            let (cy, cx, rad) = (
                r.below(h as u64) as isize,
                r.below(w as u64) as isize,
                2 + r.below(5) as isize,
            );
            let l = 1 + r.below(u64::from(k) - 1) as u8;
            for y in (cy - rad).max(0)..(cy + rad + 1).min(h as isize) {
                for x in (cx - rad).max(0)..(cx + rad + 1).min(w as isize) {
                    if (y - cy).pow(2) + (x - cx).pow(2) <= rad * rad {
                        data[y as usize * w + x as usize] = l;
                    }
                }
            }
        }
        LabelMap { data, h, w }
    }

    #[test]
    fn similarity_is_zero_to_itself_and_to_its_rotation() {
        let a = blobs(40, 30, 1, 3);
        assert!(similarity(&a, &a, 7, Rotations::All).unwrap().abs() < 1e-12);
        let mut rot = vec![0u8; 40 * 30];
        for y in 0..40 {
            for x in 0..30 {
                rot[x * 40 + (39 - y)] = a.data[y * 30 + x];
            }
        }
        let r = LabelMap {
            data: rot,
            h: 30,
            w: 40,
        };
        assert!(similarity(&a, &r, 7, Rotations::All).unwrap().abs() < 1e-12);
        assert!(
            similarity(&a, &r, 7, Rotations::None).unwrap()
                > similarity(&a, &r, 7, Rotations::All).unwrap()
        );
    }

    #[test]
    fn synthesis_keeps_area_and_is_deterministic_across_threads() {
        let ex = blobs(64, 64, 3, 2);
        let params = ShapeParams {
            patch_size: 7,
            iterations: 3,
            seed: 4,
            ..ShapeParams::default()
        };
        let run = |n: usize| {
            let pool = rayon::ThreadPoolBuilder::new()
                .num_threads(n)
                .build()
                .unwrap();
            pool.install(|| synthesize(&ex, 70, 50, None, &params, None).unwrap())
        };
        let one = run(1);
        assert_eq!(one, run(3));
        let f_ex = ex.count(1) as f64 / ex.data.len() as f64;
        let f_out = one.count(1) as f64 / one.data.len() as f64;
        assert!((f_ex - f_out).abs() < 0.01, "{f_ex} vs {f_out}");
        for method in [Method::Joint, Method::Layered] {
            let ex = blobs(64, 64, 5, 4);
            let out = synthesize_labels(&ex, 4, 60, 60, method, None, &params, None).unwrap();
            for l in 0..4 {
                let (fa, fb) = (ex.count(l) as f64 / 4096.0, out.count(l) as f64 / 3600.0);
                assert!((fa - fb).abs() < 0.02, "{method:?} label {l}: {fa} vs {fb}");
            }
        }
    }

    #[test]
    fn layer_order_follows_nesting_not_area() {
        // Background 1, rings of 2 around cores of 0; label 2 has the least area.
        let (h, w) = (60, 60);
        let mut data = vec![1u8; h * w];
        for (cy, cx) in [(15isize, 15isize), (15, 45), (45, 15), (45, 45)] {
            for y in 0..h as isize {
                for x in 0..w as isize {
                    let d2 = (y - cy).pow(2) + (x - cx).pow(2);
                    if d2 <= 100 {
                        data[y as usize * w + x as usize] = if d2 <= 64 { 0 } else { 2 };
                    }
                }
            }
        }
        let m = LabelMap { data, h, w };
        assert!(m.count(2) < m.count(0));
        assert_eq!(layer_order(&m, 3), vec![1, 2, 0]);
    }

    #[test]
    fn bad_arguments_name_the_parameter() {
        let ex = blobs(32, 32, 1, 2);
        let p = |patch_size| ShapeParams {
            patch_size,
            ..ShapeParams::default()
        };
        let err = |r: Result<LabelMap>| match r {
            Err(Error::InvalidArgument { name, .. }) => name,
            other => panic!("{other:?}"),
        };
        assert_eq!(
            err(synthesize(&ex, 40, 40, None, &p(4), None)),
            "patch_size"
        );
        assert_eq!(
            err(synthesize(&ex, 40, 40, None, &p(13), None)),
            "patch_size"
        );
        assert_eq!(err(synthesize(&ex, 5, 40, None, &p(7), None)), "size");
        let empty = LabelMap {
            data: vec![0; 1024],
            h: 32,
            w: 32,
        };
        assert_eq!(err(synthesize(&empty, 40, 40, None, &p(7), None)), "shape");
        let three = blobs(32, 32, 1, 3);
        assert_eq!(
            err(synthesize_labels(
                &three,
                3,
                40,
                40,
                Method::Layered,
                Some(&[0, 0, 1]),
                &p(7),
                None
            )),
            "order"
        );
    }
}
