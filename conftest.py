"""Test-session settings shared by pytest and the notebook kernels nbval starts."""

import os
from pathlib import Path

# One JIT cache for pytest and the notebook kernels (nbval starts them with this environment).
os.environ.setdefault("NUMBA_CACHE_DIR", str(Path(__file__).parent / ".numba_cache"))
os.environ.setdefault("NUMBA_THREADING_LAYER", "threadsafe")


try:
    import pytest
except ImportError:   # a notebook kernel without pytest
    pytest = None

if pytest is not None:
    @pytest.fixture(autouse=True)
    def _no_interrupt_carried_over():
        """An interrupt a test raised by a real signal and caught itself is not one of the next
        test's (``fusionkit._signals`` raises again one no command handled)."""
        yield
        import sys
        signals = sys.modules.get("fusionkit._signals")
        if signals is not None:
            signals.forget()
