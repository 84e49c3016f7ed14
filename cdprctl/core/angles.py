"""Angles a user types: radians unless a value ends in ``deg`` (or ``°``), and a bare value
beyond π taken for degrees typed as radians (30 would wrap to 1.4159 rad) and refused with its
value in radians. One rule for ``workspace --rpy``, ``send move rpy=`` and the gateway."""

from __future__ import annotations

import math

#: what ends a value given in degrees
DEGREES = ("deg", "°")
NAMES = ("roll", "pitch", "yaw")


def meant_degrees(text: str, value: float) -> str:
    """What an angle ``value`` typed as ``text`` beyond π likely was: degrees."""
    return f"did you mean degrees? {text}° = {math.radians(value):.4f} rad"


def degrees_hint(k: int, text: str, value: float, n: int = 3) -> str:
    """Why a bare angle ``value`` (typed ``text``, the ``k``-th of ``n``) beyond π is refused,
    with what the user likely meant; "" within ±π."""
    if abs(value) <= math.pi:
        return ""
    name = NAMES[k] if n == 3 else f"value {k + 1}"
    return (f"{name} = {text} is taken in radians and is beyond pi; "
            f"{meant_degrees(text, value)}: write it {text}deg or "
            f"{math.radians(value):.4f}")  # fmt: skip


def user_angles(parts: list[str]) -> list[float] | str:
    """Three angles (rad) from what a user typed, or why they are refused."""
    bad = "must be 3 finite numbers (rad, or each ending in deg)"
    out: list[float] = []
    for k, part in enumerate(p.strip() for p in parts):
        unit = next((u for u in DEGREES if part.endswith(u)), "")
        try:
            v = float(part.removesuffix(unit))
        except ValueError:
            return bad
        if not math.isfinite(v):
            return bad
        if not unit and (hint := degrees_hint(k, part, v, len(parts))):
            return hint
        out.append(math.radians(v) if unit else v)
    return out if len(out) == 3 else bad
