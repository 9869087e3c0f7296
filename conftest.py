"""Test-session settings shared by pytest and the notebook kernels nbval starts."""

import os
from pathlib import Path

# One JIT cache for pytest and the notebook kernels (nbval starts them with this environment).
os.environ.setdefault("NUMBA_CACHE_DIR", str(Path(__file__).parent / ".numba_cache"))
os.environ.setdefault("NUMBA_THREADING_LAYER", "threadsafe")
