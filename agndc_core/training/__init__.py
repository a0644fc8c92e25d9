"""Training code (not shipped in the Blender extension): data generation, per-scale training."""
