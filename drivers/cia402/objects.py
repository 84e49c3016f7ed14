"""Walking a ``canopen`` object dictionary (an EDS or DCF parsed by ``canopen.import_od``):
every variable, sub-indices of records and arrays included, and one variable by index and
sub-index. Shared by the set-up's DCF reader and the simulated drives' dictionary."""

from __future__ import annotations

from canopen.objectdictionary import ObjectDictionary, ODVariable


def variables(od: ObjectDictionary) -> list[ODVariable]:
    """Every variable of ``od`` in index order, sub-indices of records and arrays included."""
    out: list[ODVariable] = []
    for index in sorted(od.indices):
        obj = od[index]
        if isinstance(obj, ODVariable):
            out.append(obj)
        else:
            out.extend(obj[sub] for sub in obj.subindices)
    return out


def variable(od: ObjectDictionary, index: int, sub: int) -> ODVariable:
    """The variable at ``index``:``sub`` (``sub`` ignored for a plain variable); KeyError when
    the dictionary has none."""
    obj = od[index]
    return obj if isinstance(obj, ODVariable) else obj[sub]
