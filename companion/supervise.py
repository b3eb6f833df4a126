"""The daemon's long-lived tasks under supervision.

The daemon runs a handful of tasks for its whole life (heartbeats, the autopilot's message rates, the
alarm watchers, the precision-landing check, the ground feed) and a few one-shot ones (the sensor
stream's connection, the start-up warm-up, a resumed recovery). :func:`supervised` states what
happens when one fails:

- an exception (anything but cancellation) is logged with its traceback and the task is started again
  after a back-off that doubles from ``first_s`` to at most ``max_s`` (back to ``first_s`` after a run
  that lasted ``max_s`` or longer): a heartbeat that stops would make the autopilot drop the companion,
  a watcher that stops would miss the next low battery;
- a task meant to run for ever that returns is a fault too: logged and started again the same way;
- a one-shot task (``forever=False``) that returns is done;
- cancellation ends it at once (the daemon's shutdown).

The setpoint stream is supervised by its controller (:meth:`companion.control.VehicleController
._streaming`), the recovery by its own error handling (an internal error becomes a safe landing).
"""

from __future__ import annotations

import asyncio
import collections
import logging
import time
from collections.abc import Awaitable, Callable

__all__ = ["RESTART_FIRST_S", "RESTART_MAX_S", "supervised"]

RESTART_FIRST_S = 0.5
RESTART_MAX_S = 10.0


async def supervised(
    name: str,
    factory: Callable[[], Awaitable[object]],
    log: logging.Logger,
    *,
    forever: bool = True,
    restarts: collections.Counter[str] | None = None,
    first_s: float = RESTART_FIRST_S,
    max_s: float = RESTART_MAX_S,
) -> None:
    """Run ``factory()`` by the policy of the module docstring; each restart is counted under ``name``
    in ``restarts``."""
    delay = first_s
    while True:
        started = time.monotonic()
        try:
            await factory()
            failure = None
        except asyncio.CancelledError:
            raise
        except Exception as exc:
            failure = exc
        if failure is None and not forever:
            return
        if time.monotonic() - started >= max_s:  # it had run well: the back-off starts over
            delay = first_s
        if failure is not None:
            log.error("the %s task failed: started again in %.1f s", name, delay, exc_info=failure)
        else:
            log.error("the %s task ended by itself: started again in %.1f s", name, delay)
        if restarts is not None:
            restarts[name] += 1
        await asyncio.sleep(delay)
        delay = min(2.0 * delay, max_s)
