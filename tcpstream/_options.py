"""How a controller connects: one :class:`ClientConfig`, one :class:`ClientOptions`.

Every way of making a client -- :class:`~tcpstream.ArmClient`,
:func:`~tcpstream.connect_tcp`, :func:`~tcpstream.connect_stream`,
:meth:`~tcpstream.BlockingClient.tcp` -- takes the same options, either as a
``config=ClientConfig(...)`` or as keyword arguments.  The keyword arguments
are typed (``**options: Unpack[ClientOptions]``), so ``mypy --strict`` rejects
a misspelt option (``kye=``) in controller code; at run time an unknown
keyword is a ``TypeError`` from the dataclass.  ``ClientOptions`` mirrors
``ClientConfig`` field for field (a test pins that).
"""

from __future__ import annotations

import dataclasses
import math
import secrets
from collections.abc import Callable
from dataclasses import dataclass
from typing import TypedDict

__all__ = ["ClientConfig", "ClientOptions", "client_config"]


@dataclass(frozen=True, slots=True, kw_only=True)
class ClientConfig:
    """Everything a controller (or observer) client is told.  Checked at construction."""

    identity: str = "controller"
    """Names the controller to the arm (1..32 bytes of UTF-8); with the
    incarnation it keys the arm's exactly-once memory."""
    key: bytes | None = None
    """The pre-shared key (>= 16 bytes); None for an arm without one."""
    observer: bool = False
    """Ask for telemetry only; an observer cannot command."""
    reconnect_attempts: int = 3
    """Reconnections tried in a row after the link breaks (0: none)."""
    reconnect_delay: float = 0.5
    """Seconds before the first reconnection; doubles each attempt."""
    handshake_timeout: float = 30.0
    """Seconds a connection may take to be granted or refused."""
    max_in_flight: int = 32
    """Commands submitted and not yet answered; ``submit`` waits for room."""
    incarnation: int | None = None
    """This client's 64-bit incarnation (default: random, chosen once per
    client).  Pass one only for reproducible runs; never reuse one across
    controller restarts, or the arm may confuse the two programs' ids."""
    nonce_source: Callable[[int], bytes] = secrets.token_bytes
    """Handshake nonces; replace only to make tests reproducible."""

    def __post_init__(self) -> None:
        if isinstance(self.max_in_flight, bool) or self.max_in_flight < 1:
            raise ValueError(f"max_in_flight must be >= 1, got {self.max_in_flight!r}")
        if isinstance(self.reconnect_attempts, bool) or self.reconnect_attempts < 0:
            raise ValueError(f"reconnect_attempts must be >= 0, got {self.reconnect_attempts!r}")
        for name in ("reconnect_delay", "handshake_timeout"):
            value = getattr(self, name)
            if not (isinstance(value, int | float) and math.isfinite(value) and value >= 0):
                raise ValueError(f"{name} must be a finite number of seconds >= 0, got {value!r}")
        if self.handshake_timeout <= 0:
            raise ValueError(f"handshake_timeout must be > 0, got {self.handshake_timeout!r}")


class ClientOptions(TypedDict, total=False):
    """The fields of :class:`ClientConfig` as keyword arguments (all optional)."""

    identity: str
    key: bytes | None
    observer: bool
    reconnect_attempts: int
    reconnect_delay: float
    handshake_timeout: float
    max_in_flight: int
    incarnation: int | None
    nonce_source: Callable[[int], bytes]


def client_config(config: ClientConfig | None, options: ClientOptions) -> ClientConfig:
    """``config`` with ``options`` applied on top (either may be empty)."""
    base = config if config is not None else ClientConfig()
    return dataclasses.replace(base, **options) if options else base
