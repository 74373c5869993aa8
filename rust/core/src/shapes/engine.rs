//! The shape optimiser behind [`super::synthesize`] and [`super::synthesize_labels`]: the
//! image pyramid, the random start, the match–vote–adjust iterations of one level, and the
//! layered method's nested masks.

use std::collections::{BTreeMap, HashMap};

use rayon::prelude::*;

use super::adjust::{decide, falloff, votes, Overlay};
use super::matching::{
    exact_candidates, match_all, propagate, quotas, Index, Lookup, EXACT_WORK, K, NONE, QUOTA_SLACK,
};
use super::patches::{boundary, other_label, Geometry, Patch};
use crate::error::{Error, Result};
use crate::rng::{mix64, Rng};

use super::{LabelMap, Progress, Rotations, ShapeParams, MAX_LABELS};

/// A pixel near a layer boundary leaves the next layer's mask when less than this share of
/// the votes of the previous layer's matched exemplar patches shows the next layer there.
const SHRINK_SHARE: f32 = 0.1;

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
pub(super) struct LastMatch {
    centres: Vec<u32>,
    src: Vec<(u32, u8)>,
    dists: Vec<u32>,
}

pub(super) struct Engine<'a> {
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
    pub(super) fn new(
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
    pub(super) fn optimise(
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
    pub(super) fn layered(
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
