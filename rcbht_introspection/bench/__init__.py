"""Benchmarks run by `make bench` (measurements, not tests)."""
