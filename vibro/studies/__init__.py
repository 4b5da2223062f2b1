"""Studies over many runs: work-precision charts, validity maps, the paper's figures."""
