"""Camera response recovery: one module per published method, one registry."""

from hdrio.method_registry import MethodRegistry
from hdrio.response.debevec1997 import g_solve_Debevec1997, response_Debevec1997
from hdrio.response.linear import response_linear
from hdrio.response.robertson2003 import response_Robertson2003
from hdrio.response.sampling import SAMPLING_METHODS

RESPONSE_METHODS: MethodRegistry = MethodRegistry(
    "response", {"Debevec1997": response_Debevec1997, "linear": response_linear,
                 "Robertson2003": response_Robertson2003},
    aliases={"debevec": "Debevec1997", "robertson": "Robertson2003"},
)

__all__ = ["RESPONSE_METHODS", "SAMPLING_METHODS", "g_solve_Debevec1997",
           "response_Debevec1997", "response_Robertson2003", "response_linear"]
