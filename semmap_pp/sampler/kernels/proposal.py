"""The proposal value every kernel returns, and the weighted mix of kernel pairs.

A kernel is a callable ``kernel(rng, world, data) -> Proposal | None`` with a ``kind`` name and an
``enumerate(world, data) -> list[(Proposal, probability)]`` method that lists its whole proposal
distribution (used by the exact detailed-balance tests). ``None`` means the drawn move is impossible
from this world (no free slot, a coordinate off the lattice, ...): the chain stays where it is. The
probability of drawing such a move is simply *not* in the forward density of any real move, and every
choice the kernel makes (direction, unit, side, position, slot) is drawn from a distribution that does
not look ahead at whether the move will succeed, so the reverse density is computable the same way.

Mixing follows emcee's ``moves=[(move, weight), ...]``: a pair is chosen with a fixed probability
independent of the world, and each pair is its own reverse, so the mixing weights cancel in every
ratio.
"""

from __future__ import annotations

import bisect
from typing import NamedTuple, Sequence

from semmap_pp.world import World


class Proposal(NamedTuple):
    """A proposed world and its log proposal ratio.

    Attributes
    ----------
    world : World
        The proposed state (types of new or changed units are left for the target to assign).
    log_ratio : float
        ``log q(reverse move) - log q(forward move)``, all choice probabilities included.
    changed_slots : tuple of int
        Slots whose rectangle or activity differs from the current world.
    """

    world: World
    log_ratio: float
    changed_slots: tuple


class Mix:
    """Weighted mixture of kernels, like emcee's ``moves=[(kernel, weight), ...]``.

    Parameters
    ----------
    moves : sequence of (kernel, weight)

    Examples
    --------
    >>> import numpy as np
    >>> from semmap_pp.sampler.kernels import add_remove, shrink_dilate
    >>> mix = Mix([(add_remove, 1.0), (shrink_dilate, 3.0)])
    >>> mix.kinds, mix.probabilities
    (('add_remove', 'shrink_dilate'), (0.25, 0.75))
    """

    def __init__(self, moves: Sequence):
        moves = [(k, float(w)) for k, w in moves if float(w) > 0]
        if not moves:
            raise ValueError("a mix needs at least one kernel with positive weight")
        total = sum(w for _, w in moves)
        self.kernels = tuple(k for k, _ in moves)
        self.kinds = tuple(k.kind for k in self.kernels)
        self.probabilities = tuple(w / total for _, w in moves)
        acc, self._cdf = 0.0, []
        for p in self.probabilities:
            acc += p
            self._cdf.append(acc)
        self._cdf[-1] = 1.0

    def pick(self, rng) -> int:
        """Index of the kernel to apply next."""
        return min(bisect.bisect_right(self._cdf, rng.random()), len(self._cdf) - 1)

    def __call__(self, rng, world, data):
        """Pick a kernel and apply it: returns ``(kind_index, Proposal | None)``."""
        i = self.pick(rng)
        return i, self.kernels[i](rng, world, data)

    def __len__(self) -> int:
        return len(self.kernels)

    def __getitem__(self, i):
        return self.kernels[i], self.probabilities[i]


class Kernel:
    """A reversible kernel: a pair of half-moves chosen with probability 1/2 each, or one self-reverse move.

    The half-moves' ``log_ratio`` leaves out the 1/2 direction choice, which cancels. ``enumerate``
    lists every proposal with its probability under this kernel (direction choice included).
    """

    def __init__(self, kind: str, forward, enum_forward, backward=None, enum_backward=None):
        self.kind = kind
        self.forward, self.backward = forward, backward
        self.enum_forward, self.enum_backward = enum_forward, enum_backward

    def __call__(self, rng, world, data):
        if self.backward is None or rng.random() < 0.5:
            return self.forward(rng, world, data)
        return self.backward(rng, world, data)

    def enumerate(self, world, data) -> list:
        if self.backward is None:
            return list(self.enum_forward(world, data))
        return ([(p, 0.5 * q) for p, q in self.enum_forward(world, data)]
                + [(p, 0.5 * q) for p, q in self.enum_backward(world, data)])

    def __repr__(self) -> str:
        return f"Kernel({self.kind!r})"
