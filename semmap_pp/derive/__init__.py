"""Derived elements of a world on the lattice map: cell states, doors, objects, adjacency, unexplored areas."""
