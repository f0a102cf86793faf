"""Test material the project makes itself, with ground truth: pinhole cameras, a
z-buffered software renderer of meshes with ring and colour markers, analytic
checkerboards, marker videos of the sample face with known expressions and head motion,
and a stereo rig. Tests and benchmarks use it (as numpy.testing serves numpy's); the
library's own code never imports it."""
