"""Config checks shared by the env and algorithm configs: each raises a ValueError naming the
field, the value and what is allowed, before anything is traced."""

from __future__ import annotations

import math
import numbers


def _is_real(value) -> bool:
    return isinstance(value, numbers.Real) and not isinstance(value, bool)


def choice(name: str, value, allowed) -> None:
    if value not in allowed:
        raise ValueError(f"{name}={value!r} is invalid: allowed are {', '.join(map(repr, allowed))}.")


def positive(name: str, value, strict: bool = True) -> None:
    """A finite real number > 0 (>= 0 with strict=False); numpy scalars count, bools and strings do not."""
    ok = _is_real(value) and math.isfinite(float(value))
    if not ok or (float(value) <= 0 if strict else float(value) < 0):
        raise ValueError(f"{name}={value!r} is invalid: allowed is a finite number {'>' if strict else '>='} 0.")


def finite(name: str, value) -> None:
    """A finite real number (numpy scalars count; bools and strings do not)."""
    if not (_is_real(value) and math.isfinite(float(value))):
        raise ValueError(f"{name}={value!r} is invalid: allowed is a finite number.")


def integer(name: str, value, minimum: int, maximum: int | None = None) -> None:
    """An integer >= minimum (and <= maximum if given); numpy integers count, bools, floats and strings do not."""
    if (not isinstance(value, numbers.Integral) or isinstance(value, bool) or value < minimum
            or (maximum is not None and value > maximum)):
        allowed = f"an integer >= {minimum}" if maximum is None else f"an integer in [{minimum}, {maximum}]"
        raise ValueError(f"{name}={value!r} is invalid: allowed is {allowed}.")


def in_range(name: str, value, low: float, high: float) -> None:
    """A real number in [low, high]."""
    if not (_is_real(value) and low <= float(value) <= high):
        raise ValueError(f"{name}={value!r} is invalid: allowed is a number in [{float(low)}, {float(high)}].")


def interval(name: str, value, strict: bool = True) -> None:
    """A (min, max) tuple of finite numbers, min <= max, both > 0 (>= 0 with strict=False)."""
    ok = (isinstance(value, tuple) and len(value) == 2 and all(_is_real(v) and math.isfinite(float(v)) for v in value)
          and all(float(v) > 0 if strict else float(v) >= 0 for v in value) and float(value[0]) <= float(value[1]))
    if not ok:
        raise ValueError(f"{name}={value!r} is invalid: allowed is a tuple (min, max) of finite numbers "
                         f"{'>' if strict else '>='} 0 with min <= max.")


def below(name: str, value, bound: float, why: str, inclusive: bool = False) -> None:
    """A positive number < bound (<= with inclusive); `why` says where the bound comes from."""
    if not (_is_real(value) and 0 < float(value) and (float(value) <= bound if inclusive else float(value) < bound)):
        raise ValueError(f"{name}={value!r} is invalid: allowed is a number in (0, {bound:g}{']' if inclusive else ')'} "
                         f"({why}).")
