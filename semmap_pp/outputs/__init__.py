"""Output files other tools rely on (DESIGN.md, "Outputs other tools rely on")."""

from semmap_pp.outputs.semantic import SemanticMap, label_lattice, number_units, semantic_map
from semmap_pp.outputs.world_json import (FORMAT, dumps, png_bytes, world_dict, write_labels_png,
                                          write_world_json)

__all__ = ["SemanticMap", "semantic_map", "number_units", "label_lattice", "FORMAT", "dumps",
           "png_bytes", "world_dict", "write_labels_png", "write_world_json"]
