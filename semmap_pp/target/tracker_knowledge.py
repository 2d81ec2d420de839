"""The knowledge side of the target's :class:`~semmap_pp.target.posterior.Tracker`.

With knowledge on, a proposal's types come from the provider given the evidence of the proposed
world. :class:`KnowledgeTracking` keeps the current world's (doors, passages) between each pair
of slots, MulDoor flags, corridor pieces and evidence, edits them at the changed slots, and asks
the provider only when the evidence differs from the current world's.
"""

from __future__ import annotations

import numpy as np

from semmap_pp.target.geometry_evidence import PIECE_ITEM, knowledge_evidence, patch_knowledge_evidence


class KnowledgeTracking:
    """The knowledge evidence of a tracker's current world and of its proposals (a base of
    :class:`~semmap_pp.target.posterior.Tracker`, which holds ``post``, ``_provider`` and the
    current typing ``_typ``)."""

    def _start_knowledge(self, post, w) -> None:
        """The knowledge state of the current world ``w`` (knowledge on): its (doors, passages)
        between each pair of slots, MulDoor flags, corridor pieces and evidence."""
        self._with_doors = getattr(self._provider, "needs_doors", True)
        self._map_only = bool(getattr(self._provider, "has_map_only", False))
        # (doors, passages) between each pair of slots
        self._openings = np.zeros((w.capacity, w.capacity, 2), np.int32)
        if self._with_doors:
            cross = self._typ.cross
            for p, q in zip(*np.nonzero(np.triu(self._typ.adj, 1))):
                self._openings[p, q] = self._openings[q, p] = (
                    post.pair_openings(w.rects[p], w.rects[q])
                    if cross is None or post.same_tile(w.rects[p], w.rects[q]) else cross[p, q])
        self._many, self._pieces = self._muldoor(w, self._openings, self._typ.geometry)
        self._evidence = self._knowledge_evidence(w, self._typ.adj, self._many, self._pieces)

    def _knowledge_evidence(self, world, adj, many, pieces):
        post = self.post
        active = world.active
        units = np.flatnonzero(active).tolist()
        r = world.rects[units]
        get = post._geometry.get   # = unit_geometry by size
        items = [get(h, w) for h, w in zip((r[:, 2] - r[:, 0]).tolist(),
                                             (r[:, 3] - r[:, 1]).tolist())]
        if pieces.any():            # corridor pieces: hard corridor-like (build_evidence's rule)
            items = [PIECE_ITEM if pieces[u] else it for u, it in zip(units, items)]
        muldoor = np.flatnonzero(many & active).tolist()
        iu, ju = np.nonzero(adj)   # row-major: the pairs p < q come out sorted
        up = iu < ju
        return knowledge_evidence(units, items, muldoor,
                                  list(zip(iu[up].tolist(), ju[up].tolist())))

    def _patched_evidence(self, world, adj, many, pieces, changed):
        """:meth:`_knowledge_evidence` of a proposed world, by editing the current world's
        evidence (:func:`~semmap_pp.target.geometry_evidence.patch_knowledge_evidence`): the changed slots and the
        slots whose corridor-piece or MulDoor flag changed get their entries anew, and the
        changed slots' adjacency rows their pairs. Equal to the evidence built in full
        (tests/unit/test_posterior.py)."""
        cur = self._typ
        get = self.post._geometry.get
        active, rects = world.active, world.rects
        slots = set(changed.tolist())
        slots.update(np.flatnonzero(pieces != self._pieces).tolist())
        items = {}
        for s in slots:
            if not active[s]:
                items[s] = None
            elif pieces[s]:
                items[s] = PIECE_ITEM
            else:
                r = rects[s]
                items[s] = get(int(r[2] - r[0]), int(r[3] - r[1]))
        muldoor = {s: bool(many[s]) for s in np.flatnonzero(many != self._many).tolist()}
        drop, add = set(), set()
        oadj = cur.adj
        for s in changed.tolist():
            for t in np.flatnonzero(oadj[s] & ~adj[s]).tolist():
                drop.add((s, t) if s < t else (t, s))
            for t in np.flatnonzero(adj[s] & ~oadj[s]).tolist():
                add.add((s, t) if s < t else (t, s))
        return patch_knowledge_evidence(self._evidence, items, muldoor, sorted(drop), sorted(add))

    def _muldoor(self, world, openings, geometry):
        """``(many, pieces)``: the slots with multiple doors (bool (K,), the MulDoor evidence) and
        the room-like slots that are corridor pieces (:meth:`Posterior.corridor_pieces`), from the
        (doors, passages) ``openings`` (K, K, 2) and the geometry classes (K,); all False without
        doors."""
        if not self._with_doors:
            none = np.zeros(world.capacity, dtype=bool)
            return none, none
        counts, pieces = self.post.opening_evidence(openings, world.rects,
                                                    np.where(world.active, geometry, np.int8(-1)))
        return (counts >= self.post.model.evidence.multiple_doors) & world.active, pieces

    def _same_openings(self, world, openings, geometry, changed) -> bool:
        """Whether :meth:`_muldoor` would see the current world's inputs again: each changed slot
        keeps its presence and, when present, its geometry class, its rectangle's shorter side
        (the corridor pieces' width test) and its row of ``openings`` (symmetric: its column too).
        The MulDoor flags and corridor pieces are then the current ones."""
        if not self._with_doors:
            return True
        cur = self._typ
        ow, og, oo = cur.world, cur.geometry, self._openings
        for s in changed.tolist():
            a = world.active[s]
            if a != ow.active[s]:
                return False
            if not a:
                continue
            r, o = world.rects[s], ow.rects[s]
            if geometry[s] != og[s] or min(r[2] - r[0], r[3] - r[1]) != min(o[2] - o[0], o[3] - o[1]):
                return False
            if not np.array_equal(openings[s], oo[s]):
                return False
        return True

    def _same_evidence(self, world, adj, many, pieces, changed) -> bool:
        """Whether the evidence of the proposed world equals the current world's, checked on
        the changed slots alone (without building it): every part of the evidence is the same
        when each changed slot keeps its presence, its geometry item and its adjacency row (the
        edit touches no other row) and no unit's MulDoor or corridor-piece flag changes
        (``many``, ``pieces``: the proposed world's flags)."""
        cur = self._typ
        ow, oadj = cur.world, cur.adj
        get = self.post._geometry.get
        active, oactive = world.active, ow.active
        for s in changed.tolist():
            a = active[s]
            if a != oactive[s]:
                return False
            if not a:
                continue
            r, o = world.rects[s].tolist(), ow.rects[s].tolist()
            if (r[2] - r[0], r[3] - r[1]) != (o[2] - o[0], o[3] - o[1]) and \
                    get(r[2] - r[0], r[3] - r[1]) != get(o[2] - o[0], o[3] - o[1]):
                return False
            if adj[s].tobytes() != oadj[s].tobytes():
                return False
        return many.tobytes() == self._many.tobytes() and pieces.tobytes() == self._pieces.tobytes()

    def _knowledge_types(self, world, adj, geometry, changed, map_only=False, cross=None,
                         touched=None):
        """Types, P(SaLe) and the knowledge patch ``(openings, evidence, MulDoor flags, corridor
        pieces)`` of a proposed world (knowledge on); ``geometry`` its geometry classes (K,).
        On a tiled lattice ``cross`` holds the proposed world's openings of pairs of two tiles and
        ``touched`` the unchanged slots whose relation to a unit of another tile changed (a third
        unit's cover): their evidence is patched like the changed slots'.

        With ``map_only`` (and a provider that :attr:`has_map_only`) an uncached result comes
        back with P(SaLe) ``None``: the MAP types alone, without the marginals."""
        post = self.post
        openings = self._openings
        if cross is not None and touched.any():
            changed = np.union1d(changed, np.flatnonzero(touched)).astype(np.int64)
        if self._with_doors:
            openings = openings.copy()
            rects, active = world.rects, world.active
            for s in changed.tolist():
                openings[s, :] = 0
                openings[:, s] = 0
                if active[s]:
                    for t in np.flatnonzero(adj[s]).tolist():
                        p, q = (s, t) if s < t else (t, s)
                        openings[p, q] = openings[q, p] = (
                            post.pair_openings(rects[p], rects[q])
                            if cross is None or post.same_tile(rects[p], rects[q]) else cross[p, q])
        cur = self._typ
        if self._same_openings(world, openings, geometry, changed):
            many, pieces = self._many, self._pieces     # the same inputs as the current world's
        else:
            many, pieces = self._muldoor(world, openings, geometry)
        if self._same_evidence(world, adj, many, pieces, changed):
            return cur.world.types, cur.sale, (openings, self._evidence, many, pieces)
        ev = self._patched_evidence(world, adj, many, pieces, changed)
        patch = (openings, ev, many, pieces)
        if ev.key == self._evidence.key:
            return cur.world.types, cur.sale, (openings, self._evidence, many, pieces)
        if map_only and self._map_only:
            hit = post._cached_arrays(self._provider, ev, world.capacity)
            if hit is None:
                return (post._map_arrays(self._provider, ev, world.capacity, base=self._evidence),
                        None, patch)
            return hit[0], hit[1], patch
        types, sale = post._result_arrays(self._provider, ev, world.capacity)
        return types, sale, patch
