"""Whether joint logs identify a fitted value: a profile likelihood at ± :data:`CHANGE` of it.

A standard error from the fit's Jacobian is local: on logs made without noise it is tiny
for every value, even one the logs hardly constrain, and it does not see that a change of
one value can be made up by another (damping by friction, on a joint whose speed while its
motor saturates hardly varies). So each fitted value of a joint is moved by ``CHANGE``
(20 %) down and up, the joint's other fitted values are fitted again with it held there,
and the rise of the replay error on the joint's own windows is measured: the *profile* of
the error along that value. The value is identifiable when both rises are at least the
error's resolution, ``max(RESOLUTION, the fit's own RMS)``: the logs then tell it to within
``CHANGE``. A value at its lower bound (friction 0) is moved up only.

The reason given for a value that is not identifiable says which case it is: the change
moves the replay less than the resolution even with the other values held (the logs never
make it matter: a damping at speeds where the motor never saturates), or it does, but
fitting the others makes it up (it trades off with them).
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass

from armreach_core.sim2real.fitting import Limits, Replays, Window, fit_block, with_values
from armreach_core.sim2real.profile import PhysicsProfile

#: Relative change of a value whose effect on the replay decides whether it is identifiable.
CHANGE = 0.2
#: Smallest rise of the replay error (rad RMS) that counts as seen: below a logged position's usual noise.
RESOLUTION = 3e-4
#: Function evaluations for each refit of the other values.
REFIT_NFEV = 8


@dataclass(frozen=True)
class Verdict:
    """Whether the logs identify one value, the rises (rad RMS) behind it, and why not where they do not."""

    identifiable: bool
    rise: float
    held_rise: float
    threshold: float
    reason: str = ""


def _rise(rms: float, base: float) -> float:
    return math.sqrt(max(rms * rms - base * base, 0.0))


def judge(
    replays: Replays,
    fitted: PhysicsProfile,
    limits: Limits,
    joint: str,
    keys: Sequence[str],
    windows: Sequence[Window],
    columns: list[int] | None,
    resolution: float | None = None,
) -> dict[str, Verdict]:
    """A :class:`Verdict` for each of ``joint``'s ``keys`` in ``fitted``, on the joint's ``windows`` and ``columns``.

    ``resolution``: the least rise that counts (default ``max(RESOLUTION, the fit's own RMS)``).
    """
    base = replays.rms(fitted, windows, columns)
    threshold = max(RESOLUTION, base) if resolution is None else resolution
    verdicts = {}
    for key in keys:
        value = fitted.value(joint, key) or 0.0
        low, high, scale = limits.bounds(fitted, joint, key, keys)
        step = CHANGE * max(value, 0.1 * scale)
        others = [(joint, k) for k in keys if k != key]
        rises, held = [], []
        for moved in (value - step, value + step):
            if moved < low - 1e-12 or moved > high + 1e-12:
                continue
            candidate = with_values(fitted, {joint: {key: moved}})
            held.append(_rise(replays.rms(candidate, windows, columns), base))
            if others:
                candidate, _ = fit_block(replays, candidate, limits, others, windows, REFIT_NFEV, columns)
            rises.append(_rise(replays.rms(candidate, windows, columns), base))
        rise, held_rise = min(rises, default=0.0), min(held, default=0.0)
        ok = rise >= threshold
        reason = ""
        if not ok and held_rise < threshold:
            reason = (
                f"a {CHANGE:.0%} change moves the replay by {held_rise:.1e} rad RMS, under the resolution "
                f"{threshold:.1e}: the logs do not make it matter"
            )
        elif not ok:
            traded = ", ".join(k for _, k in others)
            reason = (
                f"a {CHANGE:.0%} change moves the replay by {held_rise:.1e} rad RMS, but refitting {traded} "
                f"makes it up to {rise:.1e} (resolution {threshold:.1e}): it trades off with {traded}"
            )
        verdicts[key] = Verdict(ok, rise, held_rise, threshold, reason)
    return verdicts


__all__ = ["CHANGE", "RESOLUTION", "Verdict", "judge"]
