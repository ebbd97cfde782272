import os
import sys

import jax

# As optimistix's tests do: float64 and strict dtype promotion, so silent int/float or
# float32/float64 mixing in the library fails loudly here.
jax.config.update("jax_enable_x64", True)
jax.config.update("jax_numpy_dtype_promotion", "strict")

sys.path.insert(0, os.path.dirname(__file__))
os.environ.setdefault("MPLBACKEND", "Agg")
