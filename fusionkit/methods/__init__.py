"""The merging methods, each behind the one interface of :mod:`fusionkit.methods.base`.

========================  ==================================================================
``--method`` name          where it lives
========================  ==================================================================
``spectral-pso``           :mod:`fusionkit.methods.paper` (the paper's method)
``consensus`` (default)    :mod:`fusionkit.methods.consensus` (adapter: ``_merge.py``)
``map-merge``              :mod:`fusionkit.methods.peers.map_merge` (chaining corrected)
``map-merge-shipped``      :mod:`fusionkit.methods.peers.map_merge` (chaining as shipped)
``hough-spectrum``         :mod:`fusionkit.methods.peers.hough_spectrum`
``fourier-mellin``         :mod:`fusionkit.methods.peers.fourier_mellin`
========================  ==================================================================

The peers' adapter to the interface is :mod:`fusionkit.methods.peers._method`. A method's
module is imported only when the method is asked for (:func:`get_method`).
"""

from __future__ import annotations

import importlib

from ..errors import InputError

__all__ = ["METHODS", "get_method"]

#: ``--method`` name -> (module under :mod:`fusionkit.methods`, factory, its arguments)
_REGISTRY = {
    "spectral-pso": ("paper", "SpectralPSO", ()),
    "consensus": ("consensus._merge", "ConsensusMethod", ()),
    "map-merge": ("peers._method", "PeerMethod", ("map-merge",)),
    "map-merge-shipped": ("peers._method", "PeerMethod", ("map-merge-shipped",)),
    "hough-spectrum": ("peers._method", "PeerMethod", ("hough-spectrum",)),
    "fourier-mellin": ("peers._method", "PeerMethod", ("fourier-mellin",)),
}

#: Method names accepted by :func:`fusionkit.pipeline.merge` and ``fusionkit merge --method``:
#: the paper's method, the consensus method and the classic peers (``map-merge-shipped``
#: chains 3+ maps in the order OpenCV does).
METHODS = tuple(_REGISTRY)


def get_method(name: str):
    """The method (:class:`~fusionkit.methods.base.Method`) registered under ``name``."""
    if name not in _REGISTRY:
        raise InputError(f"unknown method {name!r}; choose one of {', '.join(METHODS)}")
    module, factory, args = _REGISTRY[name]
    return getattr(importlib.import_module(f".{module}", __name__), factory)(*args)
