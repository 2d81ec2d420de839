"""What the knowledge engine returns for one evidence: :class:`InferenceResult`."""

from __future__ import annotations

from dataclasses import dataclass


@dataclass(frozen=True)
class InferenceResult:
    """Marginals and MAP of one evidence.

    Attributes
    ----------
    types : dict int -> ndarray (4,)
        Type marginals per unit, in ``cells.UNIT_TYPES`` order (room, corridor, hall, other).
    sale : dict (p, q) -> float
        ``P(sale(p,q))`` for each adjacent pair, ``p < q``.
    map_types : dict int -> str
        The most probable types (a ``cells.UNIT_TYPES`` name per unit), maximised jointly with
        SaLe, the soft evidence atoms summed out.
    map_cost : float
        ``-log`` of the MAP's unnormalised weight (MLN units): without soft evidence the weight
        of the soft rules the MAP world violates; with it, summed over the soft atoms' states,
        so it can be negative.
    log_z : float or None
        Log partition function over types and SaLe (exact marginals only).
    method : str
        How the marginals were computed: ``"exact"``, ``"lbp"`` or ``"mcsat"``.
    map_method : str
        How the MAP was found: ``"jt"`` (max-product on a junction tree, or per unit when
        no pair couples the MAP), ``"rc2"`` or ``"clingo"``; all exact. ``"jt+max"`` /
        ``"rc2+max"``: a soft atom tied to too many units was maximised, not summed out.
    """

    types: dict
    sale: dict
    map_types: dict
    map_cost: float
    log_z: float | None
    method: str
    map_method: str = "jt"
