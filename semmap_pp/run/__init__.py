"""One run: inputs read and checked, the target rebuilt in every process, run settings and results, the pipeline; an output folder held by one run; several runs as a batch."""
