"""Fast path: a pairwise network assembled from cached per-unit and per-pair templates.

When every rule is *pairwise-local* (checked on the AST by :func:`is_pairwise`), the ground
network of any evidence is a sum of unit factors, each depending only on that unit's evidence,
and pair factors, each depending only on an adjacent pair's evidence. Then one clingo grounding of
a single unit per evidence pattern, and of one adjacent pair per pattern pair, gives every factor
ever needed; the pair template minus its two unit templates is the pair factor. SaLe atoms only
occur in pair factors, so they are summed (or maximised) out inside the template, and inference
runs on one variable per unit (its type times its soft evidence atoms). The result is the same
network as :func:`~semmap_pp.knowledge.ground.ground` builds (tests check both against
enumeration).

Soft evidence never needs a grounding of its own: ``soft(rolike(u), p)`` only opens the atom
and puts the unit weight ``w = round(1000 log(p / (1 - p)))`` / 1000 on it (the engine's
``FRAME``), so a unit template is the template of its *structure* (each evidence atom absent,
hard or soft) grounded once with weight 0 (``p = 0.5``), plus that weight on the atom's bit; a
pair template (full pair network minus its unit templates) does not depend on the soft weights
at all. clingo therefore grounds one template per structure and structure pair, a handful per
rule set, instead of one per soft value.

A rule file is pairwise-local when: its only normal rule is ``adj(Q,P) :- adj(P,Q).``; every
constraint body is plain literals of evidence and query atoms whose arguments are variables, plus
comparisons between those variables; a body has one unit variable, or two linked by a positive
``adj`` or ``sale`` literal; and every weak constraint's terms are a constant id (unique in the
file) followed by exactly its unit variables. Anything else uses the general path.
"""

from __future__ import annotations

import hashlib
import os
import sys
import tempfile
from dataclasses import dataclass
from pathlib import Path

import clingo
import clingo.ast as cast
import numpy as np

from semmap_pp.cells import UNIT_TYPES
from semmap_pp.errors import RuleError
from semmap_pp.jitcache import cache_home
from semmap_pp.knowledge.dialect import SOFT_PREDICATES, RuleSet, parse_text
from semmap_pp.knowledge.evidence import Evidence, soft_weight
from semmap_pp.knowledge.exact import _lse, merged_potentials
from semmap_pp.knowledge.ground import FRAME, ground

_T = cast.ASTType


def _var_args(atom_node):
    sym = atom_node.symbol
    if sym.ast_type == _T.SymbolicTerm:
        return [] if sym.symbol.type == clingo.SymbolType.Function else None
    if sym.ast_type != _T.Function or sym.external:
        return None
    names = []
    for a in sym.arguments:
        if a.ast_type != _T.Variable:
            return None
        names.append(a.name)
    return sym.name, names


def _body_ok(body):
    """Unit variables of a local body, or None."""
    variables, links = set(), []
    for lit in body:
        if lit.ast_type != _T.Literal:
            return None
        atom = lit.atom
        if atom.ast_type == _T.BooleanConstant:
            continue
        if atom.ast_type == _T.Comparison:
            terms = [atom.term] + [g.term for g in atom.guards]
            if not all(t.ast_type == _T.Variable for t in terms):
                return None
            continue
        if atom.ast_type != _T.SymbolicAtom:
            return None
        va = _var_args(atom)
        if va is None or not va:
            return None
        name, args = va
        variables.update(args)
        if name in ("adj", "sale") and lit.sign == cast.Sign.NoSign and len(set(args)) == 2:
            links.append(set(args))
    if len(variables) == 1 or (len(variables) == 2 and variables in links):
        return variables
    return None


def is_pairwise(rules: RuleSet) -> bool:
    """Whether ``rules`` is in the pairwise-local fragment (see the module docstring)."""
    return pairwise_obstacle(rules) is None


def pairwise_obstacle(rules: RuleSet) -> str | None:
    """The first statement of ``rules`` that keeps it out of the pairwise-local fragment (see
    the module docstring), quoted with the reason, or None when the rule set is pairwise-local.

    >>> from semmap_pp.knowledge import load_rules
    >>> pairwise_obstacle(load_rules("rules/table3.lp")) is None
    True
    >>> print(pairwise_obstacle(load_rules("rules/halls_to_corridors.lp")))
    `nextcorr(U) :- adj(U,V); corr(V).` defines a helper atom (only `adj(Q,P) :- adj(P,Q).` may)
    """
    ids = set()
    for st in parse_text(rules.program, rules.path):
        t = st.ast_type
        if t in (_T.Program, _T.Definition):
            continue
        if t == _T.Rule:
            head = st.head
            if head.atom.ast_type == _T.BooleanConstant:
                if _body_ok(st.body) is None:
                    return f"`{st}` {_BODY}"
                continue
            if str(st) != "adj(Q,P) :- adj(P,Q)." and not (
                    head.atom.ast_type == _T.SymbolicAtom and _is_adj_closure(st)):
                return f"`{st}` defines a helper atom (only `adj(Q,P) :- adj(P,Q).` may)"
            continue
        if t == _T.Minimize:
            variables = _body_ok(st.body)
            if variables is None:
                return f"`{st}` {_BODY}"
            first, rest = (st.terms[0], st.terms[1:]) if st.terms else (None, ())
            if (first is None or first.ast_type != _T.SymbolicTerm or str(first) in ids
                    or not all(r.ast_type == _T.Variable for r in rest)
                    or sorted(r.name for r in rest) != sorted(variables)):
                return (f"`{st}`: a weak constraint's terms must be an id of its own followed by "
                        "exactly its unit variables")
            ids.add(str(first))
            continue
        return f"`{st}` is not a rule, constraint or weak constraint"
    return None


_BODY = ("reads more than two units, or two not linked by a positive adj/sale literal, or "
         "something other than plain literals and comparisons of variables")


def _is_adj_closure(st) -> bool:
    va = _var_args(st.head.atom)
    if not va or va[0] != "adj" or len(st.body) != 1:
        return False
    lit = st.body[0]
    if lit.ast_type != _T.Literal or lit.sign != cast.Sign.NoSign:
        return False
    vb = _var_args(lit.atom) if lit.atom.ast_type == _T.SymbolicAtom else None
    return bool(vb) and vb[0] == "adj" and vb[1] == va[1][::-1] and len(set(va[1])) == 2


def _dense(net, order):
    """Dense log potential of ``net`` over the variables in ``order`` (constant included)."""
    where = {v: i for i, v in enumerate(order)}
    shape = tuple(int(net.card[v]) for v in order)
    out = np.full(shape, -net.offset / 1000.0)
    for scope, table in merged_potentials(net):
        pos = [where[v] for v in scope]
        perm = sorted(range(len(scope)), key=lambda j: pos[j])
        sh = [1] * len(order)
        for j in perm:
            sh[pos[j]] = table.shape[j]
        out = out + np.transpose(table, perm).reshape(sh)
    return out


def _unit_key(ev_maps, u):
    return tuple(ev_maps[name].get(u, 0.0) for name in SOFT_PREDICATES)


def _structure(key):
    """The structure of a unit pattern: each evidence atom absent (0), hard (1) or soft (0.5,
    i.e. open with weight 0)."""
    return tuple(0.0 if p <= 0.0 else (1.0 if p >= 1.0 else 0.5) for p in key)


def _soft_terms(key):
    """``(bit, w)`` of the soft atoms of ``key`` whose weight ``w`` (thousandths) is not 0:
    ``bit`` is the atom's place in the unit's super-state (the atoms are ordered by name, the
    last one lowest, as :meth:`LocalModel._unit_order` lays them out)."""
    soft = sorted(name for name, p in zip(SOFT_PREDICATES, key) if 0.0 < p < 1.0)
    prob = dict(zip(SOFT_PREDICATES, key))
    out = []
    for j, name in enumerate(soft):
        w = soft_weight(prob[name])
        if w:
            out.append((len(soft) - 1 - j, w))
    return out


def _pattern_evidence(units_keys, adj):
    kw = {name: {} for name in SOFT_PREDICATES}
    for u, key in units_keys:
        for name, p in zip(SOFT_PREDICATES, key):
            if p > 0:
                kw[name][u] = p
    return Evidence.build([u for u, _ in units_keys], adj=adj, **kw)


# ---- templates kept on disk between processes ----------------------------------------------
#
# Every sampling process meets the same few dozen structures and structure pairs and grounded
# each with clingo (~4-7 ms each, 0.2-0.4 s per process). The grounded templates are a pure
# function of the rule program and of the code that grounds them, so they are stored under a key
# made of the program's digest, the source of the modules that compute them and the clingo and
# numpy versions: a stored table is bitwise the one a grounding would give.

#: Environment variable: directory of the template store, or ``off`` to disable it.
STORE_ENV = "SEMMAP_TEMPLATE_CACHE"


def default_store() -> Path | None:
    """The template store directory: ``$SEMMAP_TEMPLATE_CACHE``, else ``$XDG_CACHE_HOME`` (or
    ``~/.cache``) ``/semmap_pp/templates``; None when the variable is ``off`` / ``0``."""
    env = os.environ.get(STORE_ENV)
    if env is not None:
        return None if env.strip().lower() in ("", "0", "off", "no", "false") else Path(env)
    return cache_home() / "templates"


def _store_key(rules: RuleSet) -> str:
    here = Path(__file__).resolve().parent
    h = hashlib.blake2b(digest_size=16)
    for part in (rules.digest, clingo.__version__, np.__version__, FRAME):
        h.update(str(part).encode() + b"\0")
    for name in ("local.py", "ground.py", "dialect.py", "evidence.py", "exact.py"):
        h.update((here / name).read_bytes())
    return h.hexdigest()


STORE_FORMAT = "semmap_pp.templates/2"


def write_store(fh, key: str, units: dict, pairs: dict) -> None:
    """The templates as an ``.npz`` of plain arrays: unit keys and tables (concatenated, with
    offsets), pair keys and their three tables (shapes and one concatenation each)."""
    ukeys = list(units)
    pkeys = list(pairs)
    n = len(SOFT_PREDICATES)
    utab = [np.asarray(units[k][0], np.float64).reshape(-1) for k in ukeys]
    arrays = {
        "format": np.array(STORE_FORMAT), "key": np.array(key),
        "unit_keys": np.array(ukeys, np.float64).reshape(len(ukeys), n),
        "unit_k": np.array([int(units[k][1]) for k in ukeys], np.int64),
        "unit_offsets": np.cumsum([0] + [t.size for t in utab]).astype(np.int64),
        "unit_tables": np.concatenate(utab) if utab else np.zeros(0),
        "pair_keys": np.array([list(kp) + list(kq) for kp, kq in pkeys], np.float64).reshape(len(pkeys), 2 * n),
        "pair_shapes": np.array([np.shape(pairs[k][0]) for k in pkeys], np.int64).reshape(len(pkeys), 2),
    }
    for i, name in enumerate(("lse", "mx", "cond")):
        parts = [np.asarray(pairs[k][i], np.float64).reshape(-1) for k in pkeys]
        arrays[f"pair_{name}"] = np.concatenate(parts) if parts else np.zeros(0)
    np.savez(fh, **arrays)


def read_store(path, key: str) -> tuple[dict, dict]:
    """:func:`write_store`'s templates, checked: its format and key, every shape; a ValueError
    says what is wrong. Read with ``allow_pickle=False`` (an object array is refused)."""
    n = len(SOFT_PREDICATES)
    with np.load(path, allow_pickle=False) as z:
        need = {"format", "key", "unit_keys", "unit_k", "unit_offsets", "unit_tables", "pair_keys",
                "pair_shapes", "pair_lse", "pair_mx", "pair_cond"}
        if not need <= set(z.files):
            raise ValueError("not a template store")
        if str(z["format"]) != STORE_FORMAT or str(z["key"]) != key:
            raise ValueError("another format or rule set")
        uk, k, off, tab = z["unit_keys"], z["unit_k"], z["unit_offsets"], z["unit_tables"]
        if (uk.ndim != 2 or uk.shape[1] != n or k.shape != (len(uk),) or off.shape != (len(uk) + 1,)
                or off[0] != 0 or np.any(np.diff(off) < 0) or off[-1] != tab.size or np.any(k < 0)
                or np.any(k > 62)):
            raise ValueError("unit tables of the wrong shape")
        units = {}
        for i in range(len(uk)):
            t = tab[off[i]:off[i + 1]].copy()
            if t.size % (1 << int(k[i])):
                raise ValueError("a unit table of the wrong size")
            units[tuple(float(v) for v in uk[i])] = (t, int(k[i]))
        pk, shp = z["pair_keys"], z["pair_shapes"]
        if pk.ndim != 2 or pk.shape[1] != 2 * n or shp.shape != (len(pk), 2) or np.any(shp < 0):
            raise ValueError("pair tables of the wrong shape")
        sizes = np.prod(shp, axis=1) if len(shp) else np.zeros(0, np.int64)
        offs = np.concatenate([[0], np.cumsum(sizes)]).astype(np.int64)
        tables = [z[f"pair_{name}"] for name in ("lse", "mx", "cond")]
        if any(t.ndim != 1 or t.size != offs[-1] for t in tables):
            raise ValueError("pair tables of the wrong size")
        pairs = {}
        for i in range(len(pk)):
            kp, kq = tuple(float(v) for v in pk[i, :n]), tuple(float(v) for v in pk[i, n:])
            pairs[(kp, kq)] = tuple(t[offs[i]:offs[i + 1]].reshape(tuple(shp[i])).copy() for t in tables)
    return units, pairs


class LocalModel:
    """Templates of one pairwise-local rule set, cached by evidence pattern.

    Parameters
    ----------
    rules : RuleSet
    store : path or None
        Directory where grounded templates are kept between processes (see
        :func:`default_store`); None keeps them in memory only.
    """

    def __init__(self, rules: RuleSet, store=None):
        self.rules = rules
        self._units: dict = {}
        self._pairs: dict = {}
        self._flags: dict = {}
        self._reduced: dict = {}
        self._unit_tables: dict = {}
        self._structures: dict = {}
        self._raw_flags: dict = {}     # pair_flags / reduced_pair by the units' own keys
        self._raw_reduced: dict = {}
        self.groundings = 0
        self.store = None
        self.key = ""
        self._noted = False
        if store is not None:
            try:
                self.key = _store_key(rules)
                self.store = Path(store) / f"templates-{self.key}.npz"
            except OSError:
                self.store = None
            self._load()

    def _load(self) -> None:
        """Add the stored templates (none when there is no readable store). The store is an
        ``.npz`` of plain arrays read with ``allow_pickle=False``: loading it can never run code.
        A file that is not a regular file, of another key, or of the wrong shape is ignored (the
        store is only a cache) with a note on stderr, once."""
        if self.store is None or not self.store.exists():
            return
        try:
            if not self.store.is_file():
                raise ValueError("not a regular file")
            units, pairs = read_store(self.store, self.key)
        except Exception as exc:   # noqa: BLE001 - any unreadable or foreign file: the store is only a cache
            if not self._noted:
                self._noted = True
                print(f"note: {self.store}: template cache ignored ({exc}); it is written again",
                      file=sys.stderr)
            return
        for key, val in units.items():
            self._units.setdefault(key, val)
        for key, val in pairs.items():
            self._pairs.setdefault(key, val)

    def _save(self) -> None:
        """Write the grounded templates (merged with what another process stored meanwhile;
        atomic replace, errors ignored: the store is only a cache)."""
        if self.store is None:
            return
        self._load()
        units = {k: v for k, v in self._units.items() if self.structure(k) == k}
        tmp = None
        try:
            self.store.parent.mkdir(parents=True, exist_ok=True, mode=0o700)
            fd, tmp = tempfile.mkstemp(dir=self.store.parent, prefix=".templates-", suffix=".npz")
            with os.fdopen(fd, "wb") as fh:
                write_store(fh, self.key, units, dict(self._pairs))
            os.replace(tmp, self.store)
        except OSError:
            if tmp is not None:
                try:
                    os.unlink(tmp)
                except OSError:
                    pass

    def structure(self, key):
        """:func:`_structure` of ``key`` (cached)."""
        hit = self._structures.get(key)
        if hit is None:
            hit = self._structures[key] = _structure(key)
        return hit

    def unit(self, key):
        """``(log potential over super-states, n_soft_atoms)`` of a unit with pattern ``key``:
        the grounded template of its structure plus the soft atoms' unit weights."""
        hit = self._units.get(key)
        if hit is None:
            struct = self.structure(key)
            if struct == key:
                hit = self._units[key] = self.ground_unit(key)
                self._save()
            else:
                base, k = self.unit(struct)
                table = base.reshape((-1,) + (2,) * k).copy()
                for bit, w in _soft_terms(key):
                    at = [slice(None)] * (k + 1)
                    at[k - bit] = 0 if w > 0 else 1   # the state the weak constraint charges
                    table[tuple(at)] -= abs(w) / 1000.0
                hit = self._units[key] = (table.reshape(-1), k)
        return hit

    def ground_unit(self, key):
        """The unit template of ``key`` grounded by clingo (no cache; :meth:`unit` uses it for
        structures, the tests for every pattern)."""
        self.groundings += 1
        net = ground(self.rules, _pattern_evidence([(1, key)], [])).network
        order = self._unit_order(net, 1)
        return _dense(net, order).reshape(-1), len(order) - 1

    @staticmethod
    def _unit_order(net, u):
        names = {f"{p}({u})" for p in SOFT_PREDICATES}
        soft = sorted((name, v) for v, name in enumerate(net.names) if name in names)
        return [net.units.index(u)] + [v for _, v in soft]

    def pair(self, kp, kq):
        """Pair tables over (super p, super q): sum-out and max-out of SaLe, and P(sale(p,q))
        (a function of the two structures only, see the module docstring)."""
        kp, kq = self.structure(kp), self.structure(kq)
        hit = self._pairs.get((kp, kq))
        if hit is None:
            self.groundings += 1
            net = ground(self.rules, _pattern_evidence([(1, kp), (2, kq)], [(1, 2)])).network
            o1, o2 = self._unit_order(net, 1), self._unit_order(net, 2)
            sale_vars = sorted(net.sale.values())
            full = _dense(net, o1 + o2 + sale_vars)
            s1, s2 = self.unit(kp)[0], self.unit(kq)[0]
            full = full.reshape(len(s1), len(s2), -1)
            uni = s1[:, None, None] + s2[None, :, None]
            with np.errstate(invalid="ignore"):
                pair = np.where(np.isfinite(uni), full - uni, 0.0)
            lse = _lse(pair, 2)
            mx = pair.max(axis=2)
            v12 = net.sale.get((1, 2))
            if v12 is None:
                cond = np.zeros(lse.shape)
            else:
                bit = len(sale_vars) - 1 - sale_vars.index(v12)
                on = ((np.arange(pair.shape[2]) >> bit) & 1).astype(bool)
                with np.errstate(invalid="ignore"):
                    cond = np.exp(_lse(pair[:, :, on], 2) - lse)
                cond = np.where(np.isnan(cond), 0.0, cond)
            hit = self._pairs[(kp, kq)] = (lse, mx, cond)
            self._save()
        return hit

    def pair_flags(self, kp, kq):
        """Whether the pair tables of ``(kp, kq)`` ignore p's / q's soft atoms (cached)."""
        kp, kq = self.structure(kp), self.structure(kq)
        hit = self._flags.get((kp, kq))
        if hit is None:
            tables = self.pair(kp, kq)
            k1, k2 = self.unit(kp)[1], self.unit(kq)[1]
            hit = self._flags[(kp, kq)] = (all(_invariant(t, 0, k1) for t in tables),
                                           all(_invariant(t, 1, k2) for t in tables))
        return hit

    def unit_table(self, key, cut):
        """Unit table of pattern ``key`` with its low ``cut`` soft bits (all or none of them)
        summed out. The marginals and the MAP both use it: the MAP maximises the types, not the
        soft evidence atoms (``engine_ground.GroundPath.map_ground``) (cached; do not modify)."""
        hit = self._unit_tables.get((key, cut))
        if hit is None:
            hit = self.unit(key)[0]
            if cut:
                hit = _lse(hit.reshape(-1, 1 << cut), 1)
            hit.setflags(write=False)
            self._unit_tables[(key, cut)] = hit
        return hit

    def reduced_pair(self, kp, kq, cut_p, cut_q):
        """Pair tables of ``(kp, kq)`` with the low ``cut_p`` / ``cut_q`` soft bits dropped
        (units whose soft atoms no pair reads), split into what joins the network and what
        folds into the units (cached).

        Returns
        -------
        tuple
            ``(sum_table or None, (a, b) or None, sale, max_table or None, (a, b) or None)``:
            the sum-out table when it couples the pair (a zero table when only the SaLe
            marginal needs the pair's joint), its unit terms when separable, the SaLe marginal
            (a float when constant, else the conditional table), likewise for the max-out.
        """
        key = (self.structure(kp), self.structure(kq), cut_p, cut_q)
        hit = self._reduced.get(key)
        if hit is None:
            lse, mx, cond = self.pair(kp, kq)
            lse, mx, cond = (_types_only(_types_only(t, 0, cut_p), 1, cut_q)
                             for t in (lse, mx, cond))
            c = _constant_on(cond, lse)
            s_sep = separate(lse)
            s_tab = lse if s_sep is None else (np.zeros(lse.shape) if c is None else None)
            m_sep = separate(mx)
            hit = self._reduced[key] = (s_tab, s_sep, cond if c is None else c,
                                        mx if m_sep is None else None, m_sep)
        return hit

    def type_network(self, ev: Evidence) -> "TypeNetwork":
        """The network of ``ev`` over one variable per unit, ready for inference.

        A unit's soft evidence atoms are summed (maximised) out into its unit table unless a
        pair table reads them; a pair whose table is a sum of unit terms (e.g. every pair under
        ``rules/none.lp``) is folded into its units and joins no clique, separately for the
        sum-out (marginals) and the max-out (MAP) of SaLe. Exact: the joint distribution of the
        types is unchanged.
        """
        return _type_network(self, ev)

    def reduced(self, ev: Evidence):
        """``(cardinalities, sum potentials)`` of ``ev``'s network over one super-state variable
        per unit (type times soft bits), SaLe summed out in the pair tables: the network the
        local MC-SAT's junction tree is built on."""
        maps = {name: dict(ev.unary(name)) for name in SOFT_PREDICATES}
        keys = [_unit_key(maps, u) for u in ev.units]
        index = {u: i for i, u in enumerate(ev.units)}
        card, sum_pots = [], []
        for i, key in enumerate(keys):
            table, _k = self.unit(key)
            card.append(len(table))
            sum_pots.append(((i,), table))
        for p, q in ev.adj:
            i, j = index[p], index[q]
            sum_pots.append(((i, j), self.pair(keys[i], keys[j])[0]))
        return card, sum_pots


# ---- the type network: private atoms summed out, uninformative pairs factored out ------------

_TOL = 1e-9   # template tables are sums of thousandths: equal within float rounding


def _invariant(table, axis, k):
    """Whether ``table`` (super-states along ``axis``) ignores the low ``k`` soft bits there."""
    if k == 0:
        return True
    shape = table.shape[:axis] + (table.shape[axis] >> k, 1 << k) + table.shape[axis + 1:]
    t = table.reshape(shape)
    first = np.take(t, [0], axis=axis + 1)
    fin = np.isfinite(t)
    if not np.array_equal(fin, np.broadcast_to(np.isfinite(first), t.shape)):
        return False
    with np.errstate(invalid="ignore"):
        diff = np.where(fin, t - first, 0.0)
    return bool(np.abs(diff).max() <= _TOL)


def _types_only(table, axis, k):
    """``table`` restricted to soft state 0 of its super-states along ``axis``."""
    if k == 0:
        return table
    idx = np.arange(0, table.shape[axis], 1 << k)
    return np.take(table, idx, axis=axis)


def separate(table):
    """Split a log pair table into unit terms when it is a sum of them.

    Returns
    -------
    (ndarray, ndarray) or None
        ``(a, b)`` with ``table[x, y] == a[x] + b[y]`` (within rounding), or None when the table
        couples its two variables (or forbids some of their joint states).
    """
    if not np.isfinite(table).all():
        return None
    a, b = table[:, 0], table[0, :] - table[0, 0]
    if np.abs(table - a[:, None] - b[None, :]).max() > _TOL:
        return None
    return a.copy(), b.copy()


@dataclass
class TypeNetwork:
    """A pairwise network with one variable per unit, for one evidence (see :meth:`LocalModel.
    type_network`).

    Attributes
    ----------
    units : tuple of int
    shift : list of int
        Soft atoms kept in a unit's variable: its type is ``state >> shift`` (0 when no pair
        reads the unit's soft atoms, so the variable is the type itself).
    unary_sum, unary_max : list of ndarray
        Log unit tables (soft atoms not kept summed / maximised out; uninformative pair terms
        folded in).
    sum_pairs, max_pairs : list of (i, j, ndarray)
        Pair tables over ``(state_i, state_j)``, ``i < j`` unit indices, that couple their units
        (sum-out / max-out of SaLe).
    sale : dict (p, q) -> float or (i, j, ndarray)
        ``P(sale(p,q))``: a constant, or the table of ``P(sale | state_i, state_j)``; a pair with
        such a table is also in ``sum_pairs`` (with a zero table if it carries no factor).
    """

    units: tuple
    shift: list
    unary_sum: list
    unary_max: list
    sum_pairs: list
    max_pairs: list
    sale: dict

    @property
    def card(self) -> list[int]:
        return [len(t) for t in self.unary_sum]


def _constant_on(cond, table):
    """The value of ``cond`` if it is one constant over the finite entries of ``table``."""
    vals = cond[np.isfinite(table)]
    if vals.size == 0:
        return 0.0
    return float(vals[0]) if np.abs(vals - vals[0]).max() <= _TOL else None


def _fold(tables, terms):
    """``tables[i] + Σ`` of the ``(i, vector)`` terms, added in order (new arrays; the inputs
    are cached). Rows of one 2-D array when the tables have one length."""
    k = len(tables[0]) if tables else 0
    if all(len(t) == k for t in tables):
        out = np.array(tables, dtype=np.float64).reshape(len(tables), k)
        for i, v in terms:
            out[i] += v
        return list(out)
    out = [t.copy() for t in tables]
    for i, v in terms:
        out[i] += v
    return out


def _type_network(model: "LocalModel", ev: Evidence) -> TypeNetwork:
    dicts = [dict(ev.unary(name)) for name in SOFT_PREDICATES]
    units = ev.units
    keys = [tuple([d.get(u, 0.0) for d in dicts]) for u in units]
    index = {u: i for i, u in enumerate(units)}
    unit = model.unit
    softs = [unit(key)[1] for key in keys]
    collapse = [True] * len(keys)
    pairs = []
    flags_of = model._raw_flags
    for p, q in ev.adj:
        i, j = index[p], index[q]
        kk = (keys[i], keys[j])
        fl = flags_of.get(kk)
        if fl is None:
            fl = flags_of[kk] = model.pair_flags(*kk)
        if not fl[0]:
            collapse[i] = False
        if not fl[1]:
            collapse[j] = False
        pairs.append((p, q, i, j))
    cuts = [softs[i] if collapse[i] else 0 for i in range(len(keys))]
    shift, usum, umax = [], [], []
    unit_table = model.unit_table
    for i, key in enumerate(keys):
        table = unit_table(key, cuts[i])
        usum.append(table)
        umax.append(table)
        shift.append(softs[i] - cuts[i])
    sum_pairs, max_pairs, sale = [], [], {}
    add_sum, add_max = [], []
    reduced_of = model._raw_reduced
    for p, q, i, j in pairs:
        rk = (keys[i], keys[j], cuts[i], cuts[j])
        red = reduced_of.get(rk)
        if red is None:
            red = reduced_of[rk] = model.reduced_pair(*rk)
        s_tab, s_sep, c, m_tab, m_sep = red
        if s_sep is not None:
            add_sum.append((i, s_sep[0]))
            add_sum.append((j, s_sep[1]))
        if s_tab is not None:
            sum_pairs.append((i, j, s_tab))
        sale[(p, q)] = c if isinstance(c, float) else (i, j, c)
        if m_sep is not None:
            add_max.append((i, m_sep[0]))
            add_max.append((j, m_sep[1]))
        else:
            max_pairs.append((i, j, m_tab))
    usum, umax = _fold(usum, add_sum), _fold(umax, add_max)
    return TypeNetwork(tuple(units), shift, usum, umax, sum_pairs, max_pairs, sale)


# ---- the MAP side by unit, updated where the evidence changed --------------------------------

@dataclass
class MapNet:
    """The max-out side of :func:`_type_network` by unit id, for networks whose pairs are all
    separable under the max-out (no pair couples its units: under ``rules/table3.lp`` every pair,
    since SaLe is maximised out inside the pair template). Then each unit's MAP state is the
    argmax of its own table, and an edit of the evidence changes only the tables of the units
    whose evidence or cut changed and of their neighbours (:func:`map_net_update`).

    Every array is shared with the network it was updated from where the unit did not change;
    none is modified after it is made.
    """

    ev: Evidence
    keys: dict          # unit -> evidence pattern
    nbrs: dict          # unit -> neighbours, ascending (the order of the pairs in ``ev.adj``)
    cut: dict           # unit -> soft bits maximised out of its table
    shift: dict         # unit -> soft bits kept in its variable (type = state >> shift)
    umax: dict          # unit -> max-out table, separable pair terms folded in
    x: dict             # unit -> MAP state

    def map_types(self) -> dict:
        """Unit -> MAP type name, in the order of ``ev.units``."""
        x, shift = self.x, self.shift
        return {u: UNIT_TYPES[x[u] >> shift[u]] for u in self.ev.units}


def _unit_keys(ev: Evidence, units) -> dict:
    """Evidence pattern (:func:`_type_network`'s key) of each of ``units``."""
    dicts = [dict(ev.unary(name)) for name in SOFT_PREDICATES]
    return {u: tuple([d.get(u, 0.0) for d in dicts]) for u in units}


def _recut(model: "LocalModel", keys: dict, nbrs: dict, units, cut: dict, shift: dict) -> None:
    """Soft bits of each of ``units`` that no incident pair reads (``_type_network``'s cuts)."""
    flags_of = model._raw_flags
    for u in units:
        ku = keys[u]
        collapse = True
        for v in nbrs[u]:
            kk = (ku, keys[v]) if u < v else (keys[v], ku)
            fl = flags_of.get(kk)
            if fl is None:
                fl = flags_of[kk] = model.pair_flags(*kk)
            if not fl[0 if u < v else 1]:
                collapse = False
                break
        soft = model.unit(ku)[1]
        cut[u] = soft if collapse else 0
        shift[u] = soft - cut[u]


def _refold(model: "LocalModel", keys: dict, nbrs: dict, cut: dict, units, umax: dict, x: dict,
            path) -> bool:
    """Max-out table and MAP state of each of ``units`` (the unit table plus the separable pair
    terms in the order of the pairs, as :func:`_fold` adds them); False when a pair couples its
    units (the caller then takes the general path)."""
    reduced_of = model._raw_reduced
    for u in units:
        ku, cu = keys[u], cut[u]
        table = np.array(model.unit_table(ku, cu), dtype=np.float64)
        for v in nbrs[u]:
            rk = (ku, keys[v], cu, cut[v]) if u < v else (keys[v], ku, cut[v], cu)
            red = reduced_of.get(rk)
            if red is None:
                red = reduced_of[rk] = model.reduced_pair(*rk)
            m_sep = red[4]
            if m_sep is None:
                return False
            table += m_sep[0] if u < v else m_sep[1]
        if not np.isfinite(table).any():
            raise RuleError(path, "the hard rules admit no world for this evidence")
        table.setflags(write=False)
        umax[u] = table
        x[u] = int(np.argmax(table))
    return True


def map_net(model: "LocalModel", ev: Evidence, path=None) -> MapNet | None:
    """The :class:`MapNet` of ``ev`` built from scratch, or None when a pair couples its units."""
    units = ev.units
    keys = _unit_keys(ev, units)
    nbrs = {u: [] for u in units}
    for p, q in ev.adj:
        nbrs[p].append(q)
        nbrs[q].append(p)
    nbrs = {u: tuple(n) for u, n in nbrs.items()}
    cut, shift, umax, x = {}, {}, {}, {}
    _recut(model, keys, nbrs, units, cut, shift)
    if any(shift.values()):    # soft atoms a pair reads: summing them out couples the pair
        return None
    if not _refold(model, keys, nbrs, cut, units, umax, x, path):
        return None
    return MapNet(ev, keys, nbrs, cut, shift, umax, x)


def map_net_update(model: "LocalModel", base: MapNet, ev: Evidence, path=None,
                   max_share: float = 0.5) -> MapNet | None:
    """The :class:`MapNet` of ``ev`` from ``base`` (another evidence's), recomputing only what
    can differ: the cuts of the units whose evidence (pattern, neighbours) changed and of their
    neighbours (a cut depends on the unit's pattern and its neighbours', through the pair
    flags), then the tables of the units whose evidence or cut changed and of their neighbours
    (a table depends on the unit's pattern and cut and on its neighbours' patterns and cuts).
    Equal to :func:`map_net` of ``ev`` (the same arithmetic in the same order). None when a
    pair couples its units; built from scratch when more than ``max_share`` of the units
    changed."""
    old, units = base.ev, ev.units
    old_set, new_set = set(old.units), set(units)
    dirty = old_set ^ new_set
    for name in SOFT_PREDICATES:
        a, b = old.unary(name), ev.unary(name)
        if a != b:
            dirty.update(u for u, _ in set(a) ^ set(b))
    adj_old, adj_new = old.adj, ev.adj
    if adj_old != adj_new:
        added, removed = set(adj_new) - set(adj_old), set(adj_old) - set(adj_new)
        for p, q in added | removed:
            dirty.add(p)
            dirty.add(q)
    else:
        added = removed = ()
    dirty &= new_set
    if len(dirty) > max_share * max(len(units), 1):
        return map_net(model, ev, path)
    keys, nbrs = dict(base.keys), dict(base.nbrs)
    cut, shift, umax, x = dict(base.cut), dict(base.shift), dict(base.umax), dict(base.x)
    for u in old_set - new_set:
        for d in (keys, nbrs, cut, shift, umax, x):
            del d[u]
    keys.update(_unit_keys(ev, dirty))
    if added or removed:
        touched = {u for pq in (added | removed) for u in pq if u in new_set}
        change = {u: set(nbrs.get(u, ())) for u in touched}
        for p, q in removed:
            for a, b in ((p, q), (q, p)):
                if a in change:
                    change[a].discard(b)
        for p, q in added:
            change[p].add(q)
            change[q].add(p)
        for u, s in change.items():
            nbrs[u] = tuple(sorted(s))
    for u in new_set - old_set:
        nbrs.setdefault(u, ())
    ring1 = set(dirty)
    for u in dirty:
        ring1.update(nbrs[u])
    _recut(model, keys, nbrs, ring1, cut, shift)
    if any(shift[u] for u in ring1):
        return None
    # a table changes with the unit's pattern, neighbours or cut, or a neighbour's pattern or cut
    changed = dirty | {u for u in ring1 - dirty if cut[u] != base.cut[u]}
    ring2 = set(changed)
    for u in changed:
        ring2.update(nbrs[u])
    if not _refold(model, keys, nbrs, cut, ring2, umax, x, path):
        return None
    return MapNet(ev, keys, nbrs, cut, shift, umax, x)
