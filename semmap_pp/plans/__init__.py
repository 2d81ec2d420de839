"""A world.json read back and used: onto the lattice again, places and routes, diffs and hand edits."""
