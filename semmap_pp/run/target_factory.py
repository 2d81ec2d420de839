"""The target of a run, rebuilt from its rule set in every sampling process.

The rules are read once into a ``RuleSet`` (:func:`~semmap_pp.run.inputs.load_inputs`) and the
target is rebuilt from it in every process, so a rule file edited during a run does not change it.
"""

from __future__ import annotations

from dataclasses import dataclass

from semmap_pp.knowledge import KnowledgeEngine
from semmap_pp.lattice.frame import Frame
from semmap_pp.model import Model
from semmap_pp.run.inputs import Inputs
from semmap_pp.target.likelihood import LikelihoodData, remember
from semmap_pp.target.posterior import Posterior


@dataclass(frozen=True)
class TargetFactory:
    """Builds the target in each sampling process (the knowledge engine's solver state does not pickle).

    ``likelihood``: the frame's likelihood products, made once (``likelihood.prepare``) and shared
    with the chains' processes (:mod:`semmap_pp.run.shared`): each process's target reads them
    instead of making its own."""

    frame: Frame
    model: Model
    rules: object | None
    likelihood: LikelihoodData | None = None

    def __call__(self) -> Posterior:
        if self.likelihood is not None:
            remember(self.frame, self.model, self.likelihood)
        engine = None
        if self.rules is not None:
            engine = KnowledgeEngine(self.rules)
        return Posterior(self.frame, self.model, engine)


def run_target(inputs: Inputs) -> Posterior:
    """The full target of a run on ``inputs``, as W* is scored: knowledge on when it has rules."""
    post = TargetFactory(inputs.frame, inputs.model, inputs.rules)()
    post.knowledge_on = inputs.rules is not None
    return post
