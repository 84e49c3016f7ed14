"""Tension distribution algorithms behind one interface (:class:`TensionDistributor`)."""

from cdprctl.tda.solver import TensionDistributor
from cdprctl.tda.types import (
    ImposedQuantity,
    Imposition,
    TDAMethod,
    TDAOptions,
    TDAOutput,
    TDAStatus,
    tda_options_of,
)

__all__ = [
    "ImposedQuantity",
    "Imposition",
    "TDAMethod",
    "TDAOptions",
    "TDAOutput",
    "TDAStatus",
    "TensionDistributor",
    "tda_options_of",
]
