"""Experiments: run directories, evaluation, the benchmark, Ray fan-out and tuning."""
