"""A drive's DCF (or EDS) from ``[[drives.buses]] dcf``: the ParameterValues it lists, written
by SDO at set-up before cdprctl's own settings (which win where both set an object). Parsed
with the ``canopen`` package (``import_od``) outside the loop; read-only and constant objects
are skipped (a DCF records them too); objects longer than 4 bytes would need a segmented
transfer, which the driver's set-up does not do: refused by name.
"""

from __future__ import annotations

from drivers.cia402.objects import variables
from drivers.errors import DriverConfigurationError


def parameter_values(path: str, node_id: int) -> list[tuple[int, int, int, int]]:
    """(index, sub-index, value, size in bytes) of every writable ParameterValue in ``path``,
    in index order."""
    import canopen

    try:
        od = canopen.import_od(path, node_id)
    except Exception as exc:  # canopen raises ObjectDictionaryError, ValueError, OSError...
        raise DriverConfigurationError(
            f"[drives.buses] dcf {path}: cannot read it: {type(exc).__name__}: {exc}"
        ) from exc
    out = []
    for var in variables(od):
        if var.value is None or not var.writable or var.access_type == "const":
            continue
        size = len(var) // 8
        if not isinstance(var.value, int) or not 1 <= size <= 4:
            raise DriverConfigurationError(
                f"[drives.buses] dcf {path}: 0x{var.index:04X}:{var.subindex:02X} "
                f"({var.name}) is {size} bytes: the set-up writes up to 4 (expedited SDO)"
            )
        out.append((var.index, var.subindex, int(var.value), size))
    return out
