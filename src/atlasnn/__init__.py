"""atlasnn: ATLAS-NN, learnable time-scaled Hamiltonian neural networks (JAX).

The data flow of the package, one module per concept:

    config -> systems + scaling + model -> loss/collocation -> train/transfer
           -> solution -> integrators/metrics -> report/plots
"""

from atlasnn._version import __version__
from atlasnn.errors import AtlasError
from atlasnn.precision import enable_x64, x64_enabled

__all__ = ["__version__", "AtlasError", "enable_x64", "x64_enabled"]
