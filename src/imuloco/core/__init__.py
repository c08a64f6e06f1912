"""Data types: skeletons, motions, databases of clips and sensor recordings."""
