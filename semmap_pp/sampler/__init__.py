"""The sampler: the reversible kernels, the Metropolis-Hastings-Green step, the PyMC step and driver, start worlds, greedy ascent, resume files, convergence diagnostics and the posterior spread."""
