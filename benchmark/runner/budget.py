"""A wall-clock budget for an expensive step, so that a lens that makes it explode ends it with a
clear message instead of stalling the run.

The budget is a timer signal (SIGALRM): it interrupts Python code, and a long native call (one
huge matrix operation, an ONNX Runtime run) only when it returns, so a step can overrun its budget
by that call's length (a 5 s budget once ended after 25 s); the message then says how long the step
ran and why. It applies in a process's main thread (the local
executor and Ray workers run tasks there); elsewhere the step runs without a budget.
"""

from __future__ import annotations

import contextlib
import signal
import threading
import time
from collections.abc import Iterator


class BudgetExceeded(TimeoutError):
    """A step ran longer than its budget."""


@contextlib.contextmanager
def time_budget(seconds: float | None, what: str) -> Iterator[None]:
    """Run the block with at most `seconds` of wall time (None: no budget); BudgetExceeded names `what`."""
    if seconds is None or threading.current_thread() is not threading.main_thread():
        yield
        return

    started = time.perf_counter()

    def expire(signum: int, frame: object) -> None:
        # The handler runs once Python code runs again: after the native call that was running returns.
        spent = time.perf_counter() - started
        late = spent - seconds
        overrun = (f"; the budget is checked between Python operations (a signal), so a native call that was "
                   f"running finished first, {late:.1f} s past the budget" if late > max(0.5, 0.1 * seconds) else "")
        raise BudgetExceeded(f"{what} ran past its budget of {seconds:g} s (--budget-s) and was stopped after "
                             f"{spent:.1f} s{overrun}; the lens or profile makes this step explode, or give it a "
                             "larger budget")

    previous = signal.signal(signal.SIGALRM, expire)
    signal.setitimer(signal.ITIMER_REAL, seconds)
    try:
        yield
    finally:
        signal.setitimer(signal.ITIMER_REAL, 0)
        signal.signal(signal.SIGALRM, previous)
