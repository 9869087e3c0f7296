"""Three classic map-merging methods fusionkit is measured against.

* :mod:`~fusionkit.methods.peers.map_merge`: AKAZE features, RANSAC and spanning-tree chaining as
  in ROS ``multirobot_map_merge``;
* :mod:`~fusionkit.methods.peers.hough_spectrum`: Carpin's Hough-spectrum merging (2008);
* :mod:`~fusionkit.methods.peers.fourier_mellin`: Fourier-Mellin phase correlation (Reddy and
  Chatterji, 1996).

Each module has ``estimate_pair(a, b, *, seed=0, **options) -> PairEstimate`` returning the
transform from ``b``'s map frame into ``a``'s (CONTRACTS 4) with the method's own score and
accept decision.
"""

from __future__ import annotations

from . import fourier_mellin, hough_spectrum, map_merge
from ._common import CropPair, PairEstimate, crop_pair, placement_error

#: name -> pairwise estimator, for loops over all peers
ESTIMATORS = {
    map_merge.METHOD: map_merge.estimate_pair,
    hough_spectrum.METHOD: hough_spectrum.estimate_pair,
    fourier_mellin.METHOD: fourier_mellin.estimate_pair,
}

__all__ = ["PairEstimate", "CropPair", "crop_pair", "placement_error", "ESTIMATORS",
           "map_merge", "hough_spectrum", "fourier_mellin"]
