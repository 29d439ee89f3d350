"""argparse value types that refuse what the commands cannot use (NaN, infinities,
negative counts), so a bad option is a one-line usage error (exit 2) naming it."""

from __future__ import annotations

import argparse
import math


def _number(text):
    try:
        v = float(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected a number, got {text!r}") from None
    if not math.isfinite(v):
        raise argparse.ArgumentTypeError(f"expected a finite number, got {text!r}")
    return v


def finite(text):
    """A finite float."""
    return _number(text)


def nonnegative(text):
    """A finite float >= 0."""
    v = _number(text)
    if v < 0:
        raise argparse.ArgumentTypeError(f"expected a number >= 0, got {text!r}")
    return v


def fraction(text):
    """A float in [0, 1]."""
    v = _number(text)
    if not 0.0 <= v <= 1.0:
        raise argparse.ArgumentTypeError(f"expected a fraction between 0 and 1, got {text!r}")
    return v


def count(minimum):
    """An integer >= ``minimum``."""
    def parse(text):
        try:
            v = int(text)
        except ValueError:
            raise argparse.ArgumentTypeError(f"expected a whole number, got {text!r}") from None
        if v < minimum:
            raise argparse.ArgumentTypeError(f"expected a whole number >= {minimum}, got {text!r}")
        return v

    parse.__name__ = f"integer >= {minimum}"
    return parse

#: the transports a Dask scheduler is reached over from another process (``inproc://``
#: names a scheduler in this same process, which a command line cannot have)
SCHEDULER_PROTOCOLS = ("tcp", "tls", "ws", "wss", "ucx")


def scheduler_address(text):
    """A Dask scheduler's address, ``[PROTOCOL://]HOST:PORT`` with PROTOCOL one of
    :data:`SCHEDULER_PROTOCOLS` (default tcp) and PORT 1–65535, returned as given. Checked
    here because distributed's own parse error comes after its client has started, whose
    clean-up then waits out its connect timeout (two minutes) and prints a traceback."""
    protocol, sep, rest = str(text).strip().partition("://")
    if not sep:
        protocol, rest = "tcp", protocol
    host, colon, port = rest.rpartition(":")
    if protocol not in SCHEDULER_PROTOCOLS:
        raise argparse.ArgumentTypeError(
            f"expected a scheduler address PROTOCOL://HOST:PORT with PROTOCOL one of "
            f"{', '.join(SCHEDULER_PROTOCOLS)}, got {text!r}")
    if not (colon and host.strip("[]") and port.isdigit() and 1 <= int(port) <= 65535) or any(c.isspace() for c in rest):
        raise argparse.ArgumentTypeError(f"expected a scheduler address HOST:PORT (e.g. tcp://10.0.0.5:8786), got {text!r}")
    return str(text).strip()


def _display_arguments(p, top=False, progress=True):
    """--no-progress and --quiet (on the main parser and on every subcommand; ``progress``
    False: --quiet only, for a command without a progress display)."""
    default = False if top else argparse.SUPPRESS
    if not top and progress:
        p.add_argument("--no-progress", action="store_true", help="no progress display")
    p.add_argument("--quiet", "-q", action="store_true", default=default,
                   help="no progress display and no informational output (warnings and errors still go to stderr)")
