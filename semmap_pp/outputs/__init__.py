"""The output files of a run, written from its semantic map and its sampled worlds (docs/outputs.md):
world.json and labels.png (:mod:`semmap_pp.semantic.world_json`), the plan files, figures and report
(:mod:`.write`). Writers only: what they write is computed before them."""
