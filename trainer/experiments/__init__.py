"""Experiments over whole trainings: sim-to-real rows, the label-efficiency curve, the cross-domain benchmark, real-folder splits and speed benchmarks."""
