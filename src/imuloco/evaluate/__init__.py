"""Measuring reconstructions: metrics, protocols (splits, noise, placements) and the benchmark."""
