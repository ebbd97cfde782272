import os
import sys
from pathlib import Path

import jax

# As optimistix's tests do: float64 and strict dtype promotion, so silent int/float or
# float32/float64 mixing in the library fails loudly here. (Importing gearte changes no
# global state; a user turns 64-bit mode on the same way.)
jax.config.update("jax_enable_x64", True)
jax.config.update("jax_numpy_dtype_promotion", "strict")
# JAX's persistent compilation cache: a second run of the suite (and the notebooks' kernels,
# which inherit the variable) reuses compiled code instead of compiling it again.
_CACHE = os.environ.setdefault("GEARTE_TEST_JAX_CACHE", str(Path(__file__).resolve().parents[1] / ".pytest_cache" / "jax"))
jax.config.update("jax_compilation_cache_dir", _CACHE)
jax.config.update("jax_persistent_cache_min_compile_time_secs", 0.0)
os.environ.setdefault("JAX_COMPILATION_CACHE_DIR", _CACHE)

sys.path.insert(0, os.path.dirname(__file__))
os.environ.setdefault("MPLBACKEND", "Agg")
