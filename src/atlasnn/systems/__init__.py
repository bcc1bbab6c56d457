"""Hamiltonian systems: H(q, p), the vector field J∇H, built-ins, Hamiltonians written as text
or as a Python function in a file.

A new built-in system is a factory and one :func:`register_system` entry (``_builtins.py``).
"""

from atlasnn.systems._builtins import (
    BUILTIN_SYSTEMS,
    defined_by_data,
    BuiltinSystem,
    builtin_system,
    harmonic_exact,
    harmonic_oscillator,
    henon_heiles,
    nonlinear_oscillator,
    numpy_field,
    register_system,
    system_from_spec,
    with_params,
)
from atlasnn.systems._bundle_box import BundleBox
from atlasnn.systems._compile import CompiledExpression, compile_expression
from atlasnn.systems._expression import expression_system, is_syntactically_separable
from atlasnn.systems._float64 import narrow_floats, require_float64_field
from atlasnn.systems._hamiltonian import HamiltonianFn, HamiltonianSystem, ParametricFn, parametric_field
from atlasnn.systems._linear import DenseLinearPart, FourierLinearPart, LinearPart, fourier_wavenumbers
from atlasnn.systems._pdes import (fput, fput_modes, nls, nls_mass, nls_soliton, periodic_grid, sine_gordon,
                                   sine_gordon_breather)
from atlasnn.systems._python import load_python_function, python_system
from atlasnn.systems._parse import CONSTANTS, FUNCTIONS, MAX_DEPTH, MAX_EXPRESSION_LENGTH, MAX_OPERATIONS

__all__ = [
    "LinearPart",
    "FourierLinearPart",
    "DenseLinearPart",
    "fourier_wavenumbers",
    "periodic_grid",
    "fput",
    "fput_modes",
    "nls",
    "nls_soliton",
    "nls_mass",
    "sine_gordon",
    "sine_gordon_breather",
    "parametric_field",
    "require_float64_field",
    "narrow_floats",
    "HamiltonianSystem",
    "BundleBox",
    "HamiltonianFn",
    "ParametricFn",
    "with_params",
    "BuiltinSystem",
    "BUILTIN_SYSTEMS",
    "defined_by_data",
    "register_system",
    "builtin_system",
    "system_from_spec",
    "nonlinear_oscillator",
    "henon_heiles",
    "harmonic_oscillator",
    "harmonic_exact",
    "numpy_field",
    "expression_system",
    "is_syntactically_separable",
    "python_system",
    "load_python_function",
    "compile_expression",
    "CompiledExpression",
    "FUNCTIONS",
    "CONSTANTS",
    "MAX_EXPRESSION_LENGTH",
    "MAX_OPERATIONS",
    "MAX_DEPTH",
]
