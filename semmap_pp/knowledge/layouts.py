"""Evidence of hand-built floor layouts, shared by the knowledge tests and benchmarks."""

from __future__ import annotations

from semmap_pp.knowledge.evidence import Evidence


def dense_floor(n: int, cols: int = 6) -> Evidence:
    """Rows of ``cols`` rooms between corridor rows (every third row a corridor row).

    Grid neighbours are adjacent, and so are diagonal ones on alternate cells; most geometry is
    soft, as in the sampler's evidence of ambiguous units. Before the type network, exact
    inference refused such floors of 40 and 80 units (a clique of 2^24 / 2^27 states).
    """
    units = list(range(1, n + 1))
    pos = {u: divmod(u - 1, cols) for u in units}
    adj = []
    for p in units:
        for q in units:
            (r1, c1), (r2, c2) = pos[p], pos[q]
            if p < q and max(abs(r1 - r2), abs(c1 - c2)) == 1 and (
                    r1 == r2 or c1 == c2 or (r1 + c1) % 2 == 0):
                adj.append((p, q))
    corr = [u for u in units if pos[u][0] % 3 == 1]
    rooms = [u for u in units if u not in corr]
    return Evidence.build(units, colike={c: (0.9 if c % 2 else 1.0) for c in corr},
                          muldoor=corr + rooms[::5],
                          rolike={r: (0.8 if r % 3 else 1.0) for r in rooms},
                          halike={r: 0.15 for r in rooms if r % 3}, adj=adj)
