"""Drivers by name: ``@register_driver`` on a :class:`~drivers.base.WinchDriver` subclass makes
it the one ``[drives] driver = <name>`` selects; ``create_driver(model)`` builds it."""

from __future__ import annotations

from typing import TYPE_CHECKING, Any

from drivers.errors import DriverConfigurationError

if TYPE_CHECKING:
    from cdprctl.model.robot import RobotModel
    from drivers.base import WinchDriver

_REGISTRY: dict[str, type[WinchDriver]] = {}


def register_driver(cls: type[WinchDriver]) -> type[WinchDriver]:
    """Class decorator: make a driver available by its ``name``."""
    _REGISTRY[cls.name] = cls
    return cls


def driver_names() -> list[str]:
    return sorted(_REGISTRY)


def create_driver(model: RobotModel, name: str | None = None, **kwargs: Any) -> WinchDriver:
    """The driver named ``name`` (default: the config's ``[drives] driver``)."""
    key = name or model.drives.driver
    if key not in _REGISTRY:
        raise DriverConfigurationError(
            f"drives.driver = {key!r}: no such driver (registered: {', '.join(driver_names())})"
        )
    return _REGISTRY[key](model, **kwargs)
