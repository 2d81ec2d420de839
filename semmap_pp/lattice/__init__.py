"""The building lattice: the dominant orientation θ0 and the map resampled onto lattice cells (:mod:`.frame`)."""
