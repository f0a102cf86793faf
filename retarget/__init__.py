"""Facial animation retargeting from feature points.

A pure library (numpy, scipy, trimesh): no web imports and no global state. The method is
Dutreve et al. 2008 (RBF space transform, feature points as translation-only skinning
joints, ellipsoid auto-weights, partial retargeting), with the deformers of Zhang et al.
(dense and region-split RBF, Laplacian editing) and Woodward et al.'s biharmonic RBF.
"""

from retarget.errors import RetargetError

__all__ = ["RetargetError"]
__version__ = "0.1.0"
