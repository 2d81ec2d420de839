"""The knowledge engine: rule files (clingo dialect) to type and SaLe marginals and MAP types.

The only package that imports clingo and python-sat. See docs/rules.md.
"""

from semmap_pp.knowledge.dialect import RuleSet, load_rules
from semmap_pp.knowledge.engine import InferenceResult, KnowledgeEngine
from semmap_pp.knowledge.evidence import Evidence, evidence_from_facts, evidence_to_facts

__all__ = ["Evidence", "InferenceResult", "KnowledgeEngine", "RuleSet", "evidence_from_facts",
           "evidence_to_facts", "load_rules"]
