"""Tension distribution algorithms behind one interface (:class:`TensionDistributor`)."""

from cdprctl.tda.solver import TensionDistributor
from cdprctl.tda.types import (
    ImposedQuantity,
    Imposition,
    TDAMethod,
    TDAOptions,
    TDAOutput,
    TDAStatus,
)

__all__ = [
    "ImposedQuantity",
    "Imposition",
    "TDAMethod",
    "TDAOptions",
    "TDAOutput",
    "TDAStatus",
    "TensionDistributor",
]
