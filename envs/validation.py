"""Config checks shared by the env and algorithm configs: each raises a ValueError naming the
field, the value and what is allowed, before anything is traced."""

from __future__ import annotations

import math
import numbers

import numpy as np

INT32_MAX = 2**31 - 1
"""The largest integer JAX holds: it computes in int32 and float32 (64-bit types are off)."""
FLOAT32_MAX = 3.4028234663852886e38
"""The largest finite float32: a larger finite Python float becomes inf inside the compiled programs."""


def _is_real(value) -> bool:
    return isinstance(value, numbers.Real) and not isinstance(value, bool)


def _finite32(value) -> bool:
    return _is_real(value) and math.isfinite(float(value)) and abs(float(value)) <= FLOAT32_MAX


def choice(name: str, value, allowed) -> None:
    if value not in allowed:
        raise ValueError(f"{name}={value!r} is invalid: allowed are {', '.join(map(repr, allowed))}.")


def positive(name: str, value, strict: bool = True) -> None:
    """A finite real number > 0 (>= 0 with strict=False); numpy scalars count, bools and strings do not."""
    ok = _finite32(value)
    if not ok or (float(value) <= 0 if strict else float(value) < 0):
        raise ValueError(f"{name}={value!r} is invalid: allowed is a finite number {'>' if strict else '>='} 0 "
                         f"(at most {FLOAT32_MAX:.4g}, float32's largest).")


def finite(name: str, value) -> None:
    """A finite real number (numpy scalars count; bools and strings do not)."""
    if not _finite32(value):
        raise ValueError(f"{name}={value!r} is invalid: allowed is a finite number (|x| <= {FLOAT32_MAX:.4g}, float32's "
                         "largest).")


def integer(name: str, value, minimum: int, maximum: int | None = None) -> None:
    """An integer >= minimum and <= maximum (default: INT32_MAX); numpy integers count, bools, floats and strings
    do not."""
    if (not isinstance(value, numbers.Integral) or isinstance(value, bool) or value < minimum
            or value > (INT32_MAX if maximum is None else maximum)):
        if maximum is not None:
            allowed = f"an integer in [{minimum}, {maximum}]"
        elif isinstance(value, numbers.Integral) and value > INT32_MAX:
            allowed = f"an integer in [{minimum}, {INT32_MAX}] (int32, as JAX computes)"
        else:
            allowed = f"an integer >= {minimum}"
        raise ValueError(f"{name}={value!r} is invalid: allowed is {allowed}.")


def in_range(name: str, value, low: float, high: float) -> None:
    """A real number in [low, high]."""
    if not (_finite32(value) and low <= float(value) <= high):
        raise ValueError(f"{name}={value!r} is invalid: allowed is a number in [{float(low)}, {float(high)}].")


def interval(name: str, value, strict: bool = True) -> None:
    """A (min, max) tuple of finite numbers, min <= max, both > 0 (>= 0 with strict=False)."""
    ok = (isinstance(value, tuple) and len(value) == 2 and all(_finite32(v) for v in value)
          and all(float(v) > 0 if strict else float(v) >= 0 for v in value) and float(value[0]) <= float(value[1]))
    if not ok:
        raise ValueError(f"{name}={value!r} is invalid: allowed is a tuple (min, max) of finite numbers "
                         f"{'>' if strict else '>='} 0 with min <= max.")


def below(name: str, value, bound: float, why: str, inclusive: bool = False) -> None:
    """A positive number < bound (<= with inclusive); `why` says where the bound comes from."""
    if not (_is_real(value) and 0 < float(value) and (float(value) <= bound if inclusive else float(value) < bound)):
        raise ValueError(f"{name}={value!r} is invalid: allowed is a number in (0, {bound:g}{']' if inclusive else ')'} "
                         f"({why}).")


RESET_FALLBACK_LIMIT = 0.25
"""Share of a run's first resets without a valid start, target or obstacle above which its configuration is refused:
the samplers' expected rate is about 1e-6 (a few % with 2 candidates), a fallback start may collide on its first
step, and a quarter stays clear of the sampling noise of 16 resets."""


def resets_succeed(env_name: str, config, default, fallback) -> None:
    """ValueError naming the options that differ from the env's `default` config when more than
    `RESET_FALLBACK_LIMIT` of the resets' `fallback` values (their reset_fallback metric) found no valid start,
    target or obstacle: options that leave the rejection samplers almost no room."""
    values = np.asarray(fallback, np.float64).ravel()
    rate = float(values.mean()) if values.size else 0.0
    if rate <= RESET_FALLBACK_LIMIT:
        return
    changed = [f"{name}={getattr(config, name)!r}" for name in vars(config)
               if hasattr(default, name) and getattr(config, name) != getattr(default, name)]
    raise ValueError(f"env {env_name!r} with {', '.join(changed) or 'its defaults'}: {rate:.0%} of {values.size} resets "
                     "found no valid start, target or obstacle (reset_fallback): allowed are options whose resets "
                     "succeed (e.g. a smaller obstacle_radius, fewer obstacles or a larger workspace).")

