"""The emulator's interlocks: lamp setpoints clamped to 0..1, and the watchdog.

The client increments ``Watchdog`` every sample.  While it keeps changing, the lamps follow their
setpoints; when it has not changed for ``timeout_s`` (1 s, product.md) the interlock trips: lamps off
(``LampsEnabled`` false) until a client writes a new watchdog value.  Before any client has written one,
the lamps are off too.  Every trip is logged.

Example
-------
>>> w = WatchdogInterlock(timeout_s=1.0)
>>> w.lamps_enabled, w.feed(7, now=0.0), w.lamps_enabled
(False, True, True)
>>> w.feed(7, now=0.5), w.check(now=0.9), w.check(now=1.2), w.lamps_enabled, w.trips   # 7 again is no change
(False, False, True, False, 1)
>>> w.feed(8, now=2.0), w.lamps_enabled
(True, True)
>>> clamp_setpoint(1.7), clamp_setpoint(-0.2), clamp_setpoint(float("nan"))
(1.0, 0.0, 0.0)
"""

from __future__ import annotations

import logging
import math

log = logging.getLogger(__name__)

WATCHDOG_TIMEOUT_S = 1.0  # product.md: lamps off when the watchdog has not changed for 1 s


def clamp_setpoint(u: float) -> float:
    """A lamp-group setpoint as the thyristors take it: a fraction in [0, 1]; NaN means off."""
    return 0.0 if not math.isfinite(u) else min(max(u, 0.0), 1.0)


class WatchdogInterlock:
    """Lamps enabled while the watchdog changes at least every ``timeout_s``."""

    def __init__(self, timeout_s: float = WATCHDOG_TIMEOUT_S) -> None:
        self.timeout_s = float(timeout_s)
        self.lamps_enabled = False
        self.trips = 0
        self._value: int | None = None
        self._changed_at = -math.inf

    @property
    def value(self) -> int | None:
        """The watchdog value last written (``None`` before any)."""
        return self._value

    def feed(self, value: int, now: float) -> bool:
        """A client wrote the watchdog; True if the value changed (the lamps are then enabled)."""
        if value == self._value:
            return False
        self._value, self._changed_at = value, now
        if not self.lamps_enabled:
            log.info("watchdog %d: lamps enabled", value)
        self.lamps_enabled = True
        return True

    def check(self, now: float) -> bool:
        """True when the interlock trips now (the watchdog has been still for longer than the timeout)."""
        if self.lamps_enabled and now - self._changed_at > self.timeout_s:
            self.lamps_enabled = False
            self.trips += 1
            log.warning("interlock trip %d: the watchdog has not changed for %.2f s (last value %s); lamps off "
                        "until a client writes it again", self.trips, now - self._changed_at, self._value)
            return True
        return False
