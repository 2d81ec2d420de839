"""A walk over clingo's AST, read by the rule dialect's checks and the grounding bound."""

from __future__ import annotations

import clingo.ast as cast


def walk(node):
    """Yield ``node`` and every AST node below it."""
    yield node
    for key in node.child_keys:
        value = getattr(node, key)
        if value is None:
            continue
        if isinstance(value, cast.AST):
            yield from walk(value)
        else:
            for item in value:
                yield from walk(item)
