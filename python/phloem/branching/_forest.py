"""The input's trees as templates for the trees that :func:`~phloem.branching.grow` makes.

A traced input is a forest: one tree per connected structure. Each output tree copies the
topology statistics of one input tree (its root branch, and per generation the lengths of its
branches together with their numbers of children), so that a large connected input gives a
large connected output and a forest of fragments a forest. Trees are used largest first, each
once, then again from the largest: an output of the input's size repeats the input's tree
sizes, and the largest trees get the most room. Within a tree, each generation's branches are
dealt like cards: every one once, in a random order, before any comes round again.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from ._elements import _generations, _tree_roots
from .skeleton import Skeleton

#: An input is connected, one structure across its picture with stray specks beside it, when
#: its largest tree holds at least this share of its length.
CONNECTED_SHARE = 0.9


@dataclass
class InputTree:
    """One tree of the (resampled) input skeleton."""

    root: int  # index of its root branch in the skeleton
    length: float  # total length in pixels
    # per generation: (length in pixels, number of children) of each of its branches
    branches: dict[int, list[tuple[float, int]]] = field(default_factory=dict)
    # per generation: the indices into ``branches`` not dealt yet in the current round
    deck: dict[int, list[int]] = field(default_factory=dict, repr=False)

    def draw(self, generation: int, rng: np.random.Generator) -> tuple[float, int] | None:
        """A branch of this tree at ``generation`` (length, children), or None if it has none.

        Dealt without replacement: each of the generation's branches once, in an order drawn
        from ``rng``, then a new round, so that a copy of a tree keeps its template's few long
        arms (``docs/pipelines/branching/quality.md``, fifty-third session).
        """
        pool = self.branches.get(generation)
        if not pool:
            return None
        left = self.deck.get(generation)
        if not left:
            left = rng.permutation(len(pool)).tolist()
            self.deck[generation] = left
        return pool[left.pop()]


def input_trees(skeleton: Skeleton, *, min_vertices: int = 3) -> list[InputTree]:
    """The trees of ``skeleton`` whose root branch has ``min_vertices`` or more, largest first."""
    gens = _generations(skeleton)
    kids = skeleton.children()
    tree = _tree_roots(skeleton)
    trees: dict[int, InputTree] = {}
    for i, b in enumerate(skeleton.branches):
        t = trees.setdefault(tree[i], InputTree(tree[i], 0.0))
        t.length += b.length()
        t.branches.setdefault(gens[i], []).append((b.length(), len(kids[i])))
    kept = [t for t in trees.values() if len(skeleton.branches[t.root]) >= min_vertices]
    # stable for equal lengths, so the order (and the output) depends on the input only
    return sorted(kept, key=lambda t: (-t.length, t.root))


def connected(trees: list[InputTree]) -> bool:
    """Whether the largest of ``trees`` (:func:`input_trees`, largest first) holds
    :data:`CONNECTED_SHARE` of their length."""
    return bool(trees) and trees[0].length >= CONNECTED_SHARE * sum(t.length for t in trees)
