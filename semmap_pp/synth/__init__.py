"""Realistic synthetic floors with ground truth.

``generate_floor(seed)`` draws a floor plan of rectangular units (rooms, corridors, halls, L-shaped
spaces), furnishes it, drives a simulated robot through it, builds the occupancy grid a SLAM system
would produce from noisy laser scans, and returns it with its ground truth. ``write_floor`` writes
``map.yaml``/``map.pgm``, ``truth.json`` and ``truth_labels.png``. See ``docs/synthetic.md``.
"""

from semmap_pp.synth.floor import Floor, generate_floor, write_floor
from semmap_pp.synth.params import SynthParams

__all__ = ["Floor", "SynthParams", "generate_floor", "write_floor"]
