"""Synthetic test material: cameras, a software renderer and marker videos with ground truth."""
