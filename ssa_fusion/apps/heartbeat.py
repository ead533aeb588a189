"""A line every few seconds while a command's long step works: nothing long runs silent.

``with working("live", "evaluating the arms over the gap"):`` says the step when it starts,
then every `EVERY_S` seconds how long it has run (and, with `detail`, how far it is: "sim
time 3.4 of 17.5 h, 412 estimates"), from a thread of its own, so that a step busy in one
call (a fit, a plot, the graph's run) is heard too; a step that took longer than one line
says when it is done. The lines go to stderr, as `progress_lines` does; the results stay on
stdout.
"""

from __future__ import annotations

import contextlib
import sys
import threading
import time
from collections.abc import Callable, Iterator
from typing import TextIO

EVERY_S = 5.0
"""Seconds between two lines of a step that is still working."""


@contextlib.contextmanager
def working(command: str, what: str, detail: Callable[[], str] | None = None,
            every_s: float = EVERY_S, stream: TextIO | None = None) -> Iterator[None]:
    """Say ``command: what`` now, and every `every_s` s how long (`detail()`: how far) it is.

    `detail` is called from the heartbeat's thread: it reads what the step's thread writes
    (a list's length), it changes nothing. ``done in N s`` at the end of a step that took
    longer than `every_s`.
    """
    out = stream if stream is not None else sys.stderr
    t0 = time.monotonic()
    stop = threading.Event()

    def say(text: str) -> None:
        print(f"{command}: {text}", file=out, flush=True)

    def beat() -> None:
        while not stop.wait(every_s):
            extra = ""
            if detail is not None:
                with contextlib.suppress(Exception):  # a heartbeat never fails its step
                    extra = detail()
            say(f"{what}: {time.monotonic() - t0:.0f} s" + (f", {extra}" if extra else ""))

    say(f"{what} ...")
    thread = threading.Thread(target=beat, name=f"heartbeat {what}", daemon=True)
    thread.start()
    try:
        yield
    finally:
        stop.set()
        thread.join()
        took = time.monotonic() - t0
        if took >= every_s:
            say(f"{what}: done in {took:.0f} s")
