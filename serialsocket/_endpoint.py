"""The ARQ endpoint: a sans-I/O reliable, full-duplex byte stream over a lossy line.

Usage (the I/O adapter's loop)::

    ep = Endpoint(config)
    ep.connect(now)                      # or ep.listen()
    line.write(ep.data_to_send(now))
    ...on bytes from the line:   ep.receive_data(chunk, now)
    ...when now >= ep.get_timer(): ep.handle_timer(now)
    ...when now >= ep.get_send_timer(): (paced data may go out)
    ...after any of these:       line.write(ep.data_to_send(now)); handle ep.events()
    ...(ep.line_discards set: if ep.take_discard() is true, drop the line's
        unsent bytes before that write -- an expedited packet cuts in)
    ...application:              ep.send(data, now); ep.read(n, now); ep.send_eof(now)

Output pacing
-------------
When the line rate is known, the endpoint models its own UART queue (a
:class:`~serialsocket._pacer.Pacer`) and releases data packets only while
less than two full packets' worth of bytes are queued on the line.
Everything else waits inside the endpoint, where ACKs and NAKs can overtake
it -- how C-Kermit with 8 x 1000-byte packets failed on a 2400 bit/s line
without it (issue 3).  Each packet's timer starts when it finishes leaving
the UART, so queueing never counts as loss.

The effective window is the smallest of the negotiated window, the peer's
advertised window, and the bandwidth-delay bound: the packets the line can
carry in three round trips, plus five -- long enough that repairing a loss,
even one whose first resend is lost too, never stalls the window (see
``_compute_effective_window``).
"""

from __future__ import annotations

import logging
import math
from collections import deque
from dataclasses import dataclass, replace

from ._checks import BlockCheck
from ._config import (
    _ACK_WIRE,
    IDLE_COPY_MIN_PACKETS,
    MAX_WINDOW,
    UNHINTED_INIT_TIMEOUT,
    UNMEASURED_DEAD_AFTER,
    EndpointConfig,
)
from ._encoding import PRINTABLE
from ._errors import LocalProtocolError, RemoteProtocolError
from ._events import (
    Connected,
    ConnectionAborted,
    ConnectionClosed,
    ConnectionRequested,
    EndOfStream,
    Event,
    LinkDead,
)
from ._expedited import (
    EXPEDITED_MAX_BYTES,
    EXPEDITED_WINDOW,
    URGENT,
    URGENT_ACK,
    ExpeditedReceiver,
    ExpeditedSender,
)
from ._fec import (
    CORRECTED_TYPE,
    REPAIR_MAX_LENGTH,
    REPAIR_TYPE,
    apply_repair,
    build_corrected,
    repair_field,
    trailer_length,
)
from ._latest import (
    LATEST,
    LATEST_ACK,
    LATEST_LEAD,
    LATEST_MAX_BYTES,
    LatestReceiver,
    LatestSender,
)
from ._length import LADDER, LengthChooser
from ._pacer import TIME_EPSILON, Pacer
from ._packet import Packet, _crc16_packet, build_packet, data_capacity
from ._params import (
    EARLY_ENCODING,
    EARLY_INIT_LIMIT,
    LANE_EARLY,
    LANE_FLIGHT,
    LONG_SEQ_MODULUS,
    MAX_FLIGHT_LENGTH,
    MAX_FLIGHT_PACKETS,
    TIMEOUT_HINT_MAX,
    DataCodec,
    Flight,
    InitParameters,
    Negotiated,
    decode18,
    encode18,
    flight_format,
    negotiate,
    self_agreement,
)
from ._parser import PacketParser, PacketReceived, RejectReason
from ._rate import PAIR_FASTER, RateEstimator, RateMark
from ._receiver import Receiver
from ._rtt import RttEstimator
from ._sender import Outstanding, Sender
from ._state import (
    CONNECTED,
    DEAF,
    LIVE,
    PEER_MAY_ABORT,
    TERMINAL,
    WRITABLE,
    State,
    Trigger,
    allowed,
    transition,
)
from ._wire import EXTENDED_HEADER_LENGTH, NORMAL_HEADER_LENGTH, PacketType, tochar, unchar

__all__ = ["Endpoint", "EndpointStatistics"]

log = logging.getLogger(__name__)

_INIT_MIN_FIELD = 12
"""An ACK carrying at least this many data characters is an init answer (26 or
more); data ACKs carry two or three (next expected, window, optional poll
flag), eight or nine with long sequence numbers (PROTOCOL.md section 9)."""

_DAMAGE = frozenset(
    {
        RejectReason.BAD_CHECK,
        RejectReason.TRUNCATED,
        RejectReason.BAD_LENGTH,
        RejectReason.BAD_HEADER,
        RejectReason.TOO_LONG,
    }
)
_CRC16 = BlockCheck.CRC16
_ACK_C = ord(PacketType.ACK)
_DATA_C = ord(PacketType.DATA)
NAK_HORIZON_SLACK = 0.1
"""The share of the two delays a NAK may arrive early and still be taken as
about our last copy (:meth:`Endpoint._nak_horizon`)."""
_CORRECTED_C = ord(CORRECTED_TYPE)
_ESTABLISHED = State.ESTABLISHED
_FAILED = State.FAILED
_T_INIT = PacketType.INIT
_T_ERROR = PacketType.ERROR
_T_ACK = PacketType.ACK
_T_NAK = PacketType.NAK
_T_DATA = PacketType.DATA
_T_EOF = PacketType.EOF
"""(Enum member lookups cost a descriptor call each in Python 3.11: the
per-packet paths use these.)"""

_ACKS: dict[int, bytes] = {}
_ACKS_BOUND = 4096
"""Cached plain CRC-16 ACKs (``_queue_ack``): one per (SEQ, next expected,
window) in use -- a few hundred on a steady link; cleared when full."""

_ERROR_TEXT_MAX = 80
"""E-packet reasons are cut to this many characters: one normal packet, readable in a trace."""

DAMAGED_KEPT = 16
"""Damaged packets a receiver keeps for a repair packet to mend (PROTOCOL.md
15.6): a repair comes a round trip or more after the damage, and at 1e-3 a
window of 31 packets of 256 characters brings seven damaged ones.  (Four
kept: 0.787 of the 1e-3 line on virtual time, 24 seeds; sixteen 0.790, as
many as 32.)  At most 16 x 9024 bytes."""

REPAIR_TRIES = 2
"""Held packets one repair packet may try: each try is one more chance for
damage the check misses (PROTOCOL.md 15.4), so few; the one whose SEQ
character matches first."""

REPAIR_MIN_LENGTH = 96
"""The shortest data packet (MARK through CHECK) whose first resend is a
repair packet: the repair is 15-30 characters, and when it mends nothing
the packet waits a round trip more."""

REPAIR_END_HITS = 0.15
"""At the end of a transfer (nothing new to send) a repair that mends
nothing idles the line for a round trip: it goes only while the packet's
expected damaged characters at the measured rate are this few."""

DUP_ACK_SLACK = 0.9
"""A copy of a packet we acknowledged less than this many smoothed round
trips ago is not acknowledged again (:meth:`Endpoint._ack_on_its_way`):
taken at 0.9 as the NAK horizon is (``NAK_HORIZON_SLACK``)."""

ACKED_KEPT = 256
"""Packets whose last ACK time is kept for :data:`DUP_ACK_SLACK`."""

DOUBLE_FROM_COPY = 3
"""The copy of a packet from which a resend goes out twice on a long line:
the third (its first resend was lost too)."""

LONG_REPAIR_ROUND_TRIPS = 6
"""Round trips of packets kept unacknowledged with long sequence numbers (the
classic bound keeps three, see ``_compute_effective_window``)."""

BUFFER_ROUND_TRIPS = LONG_REPAIR_ROUND_TRIPS + 1
"""Round trips of line data the receive buffer grows to hold (see
``Endpoint._size_receive_buffer``): those of the repair horizon, and one for
data delivered but not yet read."""

PEER_LENGTH_DECAY = 0.98
"""Per data packet received, the peer's recent longest packet decays by this
factor towards the packets it sends now: 512 down to 100 in 80 packets."""

TUNE_EARLY = 4
"""Receive-buffer autotuning looks at what arrived after a round trip over
this many (:meth:`Endpoint._autotune`)."""

PAIR_QUEUED = 1.5
"""A packet whose modelled departure is this many of its transmit times after
its handing went behind another: with that one, handed at the same instant,
a rate pair (:meth:`Endpoint._pair_verdict`)."""

FIRST_FLIGHT_RATE = 960.0
"""Characters a second (9600 bit/s) the first flight assumes at most, with no
rate yet: it covers the init exchange's round trip at that rate, about when
the rate pair's verdict comes back (see _compute_effective_window)."""

FLIGHT_SECONDS = 1.0
"""Seconds of line a first flight sent before the answer covers at most
(PROTOCOL.md 14): at the line's hinted rate, else at
:data:`FIRST_FLIGHT_RATE` (960 characters).  The round trip it fills is
unknown; this is the unhinted init's first timeout, the wait the connector
commits to anyway, and what a listener that does not take the flight costs
the line."""

FLIGHT_LENGTH_FACTOR = 2
"""A first flight's packets are this many times the starting length (see
:meth:`Endpoint._plan_flight`)."""

FIRST_FLIGHT_MIN = 4
"""Packets the first flight takes at least: the rate pair and two behind it."""

FINAL_ACK_COPIES = 2
"""Extra copies of the last ACK when a close completes (both EOFs done)."""

DATA_GAP_SILENCE = 4
"""``dead_after`` is at least this many of the recent largest gaps between the
peer's data packets: the next may be twice as long (the measured length at
most doubles a step) and one may be lost."""

PREEMPT_AFTER = 0.05
"""Seconds of earlier bytes in the UART an expedited packet waits behind at
most when the line can drop them (:attr:`Endpoint.line_discards`): beyond
that it cuts in (PROTOCOL.md 11, "Cutting in")."""

PEER_TIMEOUT_SILENCE = 2
"""A listener's ``dead_after``, before it measures the round trip, is at
least this many of the connector's initial timeout (its init's TIMEOUT
field; twice as many when the field is at its largest): that timeout is
the connector's hints' round trip and a quarter more, and the listener
hears nothing between its answer and the connector's first data, a round
trip later (PROTOCOL.md 5)."""

OUTAGE_ROUND_TRIPS = 2
"""Once the round trip is measured, ``dead_after`` rides out an outage of this
many measured round trips, plus two retransmission timeouts to repair it."""


@dataclass(frozen=True, slots=True, kw_only=True)
class EndpointStatistics:
    """A snapshot of an endpoint, in the terms an operator console shows.

    Sequence numbers are absolute counts since the connection began (the wire
    carries them mod 64).  Times are seconds.
    """

    state: str
    send_next: int
    send_base: int
    receive_expected: int
    window: int
    effective_window: int
    peer_window: int
    in_flight: int
    retransmit_queue: int
    packets_sent: int
    packets_received: int
    wire_bytes_sent: int
    wire_bytes_received: int
    bytes_queued: int
    bytes_acknowledged: int
    bytes_in_flight: int
    bytes_delivered: int
    bytes_readable: int
    eof_received: bool
    retransmissions: int
    timeouts: int
    fast_retransmits: int
    naks_sent: int
    naks_received: int
    duplicates_received: int
    out_of_window: int
    dropped_buffer_full: int
    ignored_packets: int
    check_failures: int
    rejected: int
    resyncs: int
    garbage_bytes: int
    smoothed_rtt: float | None
    timeout: float
    line_backlog: float
    long_sequence: bool = False
    """Long sequence numbers are in use (both ends offered them)."""
    receive_buffer: int = 0
    """Bytes the receiver may hold now: the configured ``receive_buffer``, grown
    with the bandwidth-delay product up to ``buffer_cap``."""
    buffer_capped: bool = False
    """The bandwidth-delay product asked for more receive buffer than
    ``buffer_cap``: the cap, not the line, may limit speed."""
    rtt_variation: float = 0.0
    """The round trip's smoothed variation (RFC 6298's RTTVAR), s."""
    base_rtt: float | None = None
    """The least plausible round trip measured: the path without queueing, s."""
    line_rate: float | None = None
    """The line rate the endpoint paces and times by, bits/s: the hint until
    the ACK clock measures the line, then the measurement (None: unknown,
    unpaced)."""
    measured_rate: float | None = None
    """The largest recent delivery-rate sample from the ACK clock, bits/s."""
    queue_delay: float = 0.0
    """Seconds the latest acknowledged packet waited in a queue outside the
    endpoint (a tty buffer, a relay): 0 when pacing keeps the path empty."""
    expedited: bool = False
    """The expedited lane was negotiated (PROTOCOL.md section 11)."""
    expedited_sent: int = 0
    """Expedited messages given to :meth:`Endpoint.send_expedited`."""
    expedited_received: int = 0
    """Expedited messages delivered whole from the peer."""
    expedited_unacknowledged: int = 0
    """Expedited fragments sent and not yet acknowledged, plus messages waiting."""
    expedited_refused: int = 0
    """Expedited fragments not taken because the inbox was full (resent later)."""
    latest: bool = False
    """The latest-value lane was negotiated (PROTOCOL.md section 12)."""
    latest_offered: int = 0
    """Values given to :meth:`Endpoint.send_latest`."""
    latest_coalesced: int = 0
    """Values replaced by a newer one before they reached the line."""
    latest_sent: int = 0
    """Values handed to the line (each once; resends are ``latest_resent``)."""
    latest_resent: int = 0
    """Resends of the newest value after its timer ran out with nothing newer."""
    latest_received: int = 0
    """Values delivered from the peer (copies not counted)."""
    latest_superseded: int = 0
    """Received values replaced by a newer one before they were read."""
    idle_copies: int = 0
    """Extra copies of unacknowledged packets sent while the line would have
    idled (``EndpointConfig.idle_copies``); not counted as retransmissions."""
    doubled_resends: int = 0
    """Resends of packets already resent once, sent twice on a long line
    (PROTOCOL.md 4.4); the second copy is not counted in ``retransmissions``."""
    preemptions: int = 0
    """Times an expedited message had the UART's queue dropped to go first
    (:attr:`Endpoint.line_discards`, PROTOCOL.md 11)."""
    preempted_resends: int = 0
    """Packets sent again because such a drop may have cut them; counted in
    ``retransmissions`` but not as losses."""
    early_sent: int = 0
    """Bytes of our stream our connection request carried (early data,
    PROTOCOL.md section 13)."""
    early_delivered: int = 0
    """Of those, bytes the listener's answer says it delivered (the rest, if
    any, went as ordinary data)."""
    early_received: int = 0
    """Bytes of the peer's stream delivered from its connection request."""
    flight_announced: int = 0
    """The most packets our request's first flight announced (PROTOCOL.md
    section 14), 0 without one."""
    flight_packets: int = 0
    """Data packets we sent in a first flight, before the listener's answer."""
    flight_refused: int = 0
    """Of those, packets the listener did not take: their bytes went again
    after the answer (counted once, not as retransmissions)."""
    flight_received: int = 0
    """Data packets of the peer's first flight that arrived (copies
    included): taken, or before the window if not taken."""
    correction: bool = False
    """Corrected data packets were agreed (PROTOCOL.md section 15)."""
    corrected_sent: int = 0
    """Data packets we sent with sums (``d``; first sends and resends)."""
    repaired: int = 0
    """Packets from the peer whose check failed and that their sums repaired
    (each one a resend saved): ``d`` packets, and ``D`` packets mended by a
    repair packet (PROTOCOL.md 15.6)."""
    repairs_sent: int = 0
    """Repair packets we sent (``r``: the sums of a ``D`` packet the peer
    lost, in place of resending it whole; PROTOCOL.md 15.6)."""
    duplicate_acks_held: int = 0
    """Copies of packets we had acknowledged less than 0.9 round trips
    before that we did not acknowledge again (our ACK was still on its way:
    a netcat listener's EOF, resent while our data queue held our ACK, drew
    eight ACKs, 0.5 s of a 2400 bit/s line)."""
    repairs_failed: int = 0
    """Repair packets from the peer that mended nothing we held (the packet
    was lost whole, or damaged beyond the sums): each one answered with a
    NAK, and the packet comes again whole."""
    packet_length: int = 0
    """The length (MARK through CHECK) new data packets are cut to: measured
    from the losses unless ``max_packet_length`` fixes it (PROTOCOL.md 4.7)."""
    byte_error_rate: float | None = None
    """Data packets lost per wire character sent, recent ones weighted most:
    the error rate the packet length is chosen for (None: nothing sent)."""


class Endpoint:
    """One side of a serialsocket link (sans-I/O).

    Args:
        config: what this side wants; see :class:`EndpointConfig`.

    Every method that can change what goes on the line takes ``now``, a
    monotonic time in seconds supplied by the caller.  Nothing inside reads a
    clock, sleeps, or touches a file descriptor.
    """

    # Per-connection state, (re)initialised by _reset_connection().
    _negotiated: Negotiated | None
    _pending_request: Negotiated | None
    _sender: Sender
    _receiver: Receiver
    _control: list[bytes]
    _events: deque[Event]
    _send_check: BlockCheck
    _encoding: DataCodec  # a prefix profile or a dense codec
    _capacity: int
    _clock: float
    _last_heard: float
    _last_probe: float
    _last_data_at: float | None
    _data_gap: float
    _init_deadline: float
    _connect_deadline: float
    _linger_until: float
    _dead_after: float
    _close_deadline: float
    _close_patience: float
    _close_patience_given: float | None
    _close_progress_at: float
    _close_mark: tuple[int, int]
    _peer_data_seen: bool
    _abort_reason: str | None
    _error_sent_at: float
    _init_sent_at: float
    _first_init_at: float
    _init_transmissions: int
    _answer_sent_at: float
    _answers: int
    _answer_span: float
    _peer_timeout: float
    """Seconds from our first answer to the latest copy of the init heard after it."""
    _window_key: tuple[int, float | None, int, float | None, int] | None
    _backlog_at: float
    _window_cached: int
    _long_seq: bool
    _adaptive: bool
    """The data packet length is measured (no ``max_packet_length``)."""
    _length: LengthChooser
    _peer_length: int
    """The peer's recent longest data packet, decaying by 2 % a packet (our
    starting length until its first; at least 96): what our ACKs may wait
    behind in its queue."""
    _mean_wire: float
    """Wire bytes of recent new data packets (a moving mean over about eight)."""
    _buffer_capped: bool
    _tune_at: float
    _tune_taken: int
    _answer_with: InitParameters | None
    _xsend: ExpeditedSender
    _xrecv: ExpeditedReceiver
    _lsend: LatestSender
    _lrecv: LatestReceiver
    _early: bytes | None
    """Our early data, fixed at the first init (None: no init sent yet)."""
    _early_chars: int
    """Characters the early data added to the init (XEARLY)."""
    _early_in: bytes | None
    """The peer's early data, taken, delivered at establishment."""
    _flight: Flight | None
    """Our first flight's announcement, fixed at the first init (PROTOCOL.md 14)."""
    _flight_bytes: bytearray
    """The bytes our first flight took from the send queue, in order (put
    back if the listener does not take it)."""
    _flight_in: Flight | None
    """The first flight the request we answered announced."""
    _flight_taken: bool
    """We took that first flight: its packets are data of this connection."""
    _flight_data_seen: bool
    """A data packet of the peer's first flight (sequence number within its
    announcement) arrived; :attr:`_peer_data_seen` is for data beyond it."""
    _accepted_init: bytes | None
    """The data field of the request we answered (a resend repeats it)."""
    _flight_floor: float
    """While the line's rate is unmeasured after our first flight: the
    slowest rate, characters a second, the init exchange allows (0: none;
    :meth:`_time_flight`)."""
    _flight_ahead: int
    """Characters of a first flight not taken that still hold the line
    ahead of what is sent after it (while :attr:`_flight_floor`)."""
    _flight_past: int
    """The first sequence number sent after the answer: once it is
    acknowledged the flight's queue has drained (:attr:`_flight_floor` 0)."""
    _flight_wire: int
    """Characters of our first flight's packets handed to the line."""
    _init_chars: int
    """Characters of our init on the line."""
    _answer_chars: int
    """Characters of the answer to it, about (header and check)."""

    def __init__(self, config: EndpointConfig | None = None) -> None:
        self.config = config or EndpointConfig()
        cfg = self.config
        # The longest packet we receive (announced), and the length data
        # packets start at; they are equal unless the length is measured
        # (no max_packet_length, PROTOCOL.md 4.7).
        self._max_length = cfg.receive_max_packet_length()
        self._start_length = cfg.derived_max_packet_length()
        self._mine = InitParameters.mine(
            max_packet_length=self._max_length,
            window=cfg.window,
            check=cfg.check,
            encoding=cfg.encoding,
            timeout_hint=cfg.initial_timeout(),
            long_window=self._long_offer(),
            features=cfg.init_features(),  # XCAPAS offers (PROTOCOL.md 10)
            lanes=cfg.init_lanes(),  # XLANES (PROTOCOL.md 12)
        )
        # No type-1 E fallback: a telelink peer sends E with the check in
        # force, and a D damaged into an E must not pass a 6-bit checksum.
        self._parser = PacketParser(
            max_length=self._max_length,
            check=BlockCheck.CRC16,
            init_check=BlockCheck.CRC16,
            init_max_length=EARLY_INIT_LIMIT,  # an I may carry early data (PROTOCOL.md 13)
            error_fallback=False,
        )
        self._rate = RateEstimator(self._rate_hint())
        self._pacer = Pacer(
            self._tx, paced=cfg.line_rate is not None, full_packet=self._start_length + 1
        )
        self._rtt = RttEstimator(
            floor=self._timeout_floor(self._start_length, self._start_length),
            ceiling=math.inf,  # set with dead_after when a connection starts (_ceiling)
            initial=cfg.initial_timeout(),
        )
        self._derived_dead_after = cfg.derived_dead_after()  # (once per ACK in _liveness)
        self._counters: dict[str, int] = dict.fromkeys(
            (
                "packets_sent",
                "packets_received",
                "early_delivered",
                "early_received",
                "wire_bytes_sent",
                "wire_bytes_received",
                "retransmissions",
                "timeouts",
                "fast_retransmits",
                "naks_sent",
                "naks_received",
                "duplicates_received",
                "out_of_window",
                "dropped_buffer_full",
                "ignored_packets",
                "idle_copies",
                "doubled_resends",
                "preemptions",
                "preempted_resends",
                "flight_packets",
                "flight_refused",
                "flight_received",
                "corrected_sent",
                "repairs_sent",
                "repairs_applied",
                "repairs_failed",
                "duplicate_acks_held",
            ),
            0,
        )
        self.line_discards = False
        """The I/O adapter can drop bytes handed to the line and not yet
        sent (a port's output flush): an expedited packet then cuts in
        ahead of them (:meth:`take_discard`, PROTOCOL.md 11).  The drivers
        set it from the port (``can_discard_output``); off by default."""
        self._discard_due = False
        self._connects = 0  # first flights announced, for their nonces
        self._control_done_at: float = -math.inf  # (set per connection)
        self._state: State = State.IDLE
        self._reset_connection()

    # -- public: lifecycle --------------------------------------------------------

    @property
    def state(self) -> State:
        """The connection state (see :mod:`serialsocket._state`)."""
        return self._state

    @property
    def parameters(self) -> Negotiated | None:
        """The negotiated parameters once connected."""
        return self._negotiated

    def listen(self) -> None:
        """Wait for a peer's init packet (the manipulator side)."""
        self._go(Trigger.LISTEN)

    def connect(self, now: float) -> None:
        """Send an init packet and retransmit it until answered or the deadline passes.

        Bytes already queued with :meth:`send` ride in the init packet, up to
        ``EndpointConfig.early_data`` of them (early data, PROTOCOL.md
        section 13): a listener that takes them delivers them one one-way
        delay after this call, before its answer is back.  Whatever it does
        not take goes as ordinary data once connected, so each byte is
        delivered exactly once either way."""
        self._go(Trigger.CONNECT)
        self._connect_deadline = now + self.config.derived_connect_timeout()
        self._send_init(now)

    def accept(self, now: float) -> None:
        """Accept the pending connection request (only with ``auto_accept=False``)."""
        if self._pending_request is None or self._state is not State.LISTEN:
            raise LocalProtocolError("accept() needs a pending ConnectionRequested in LISTEN")
        self._establish(self._pending_request, now, answer=True)

    def refuse(self, reason: str, now: float) -> None:
        """Refuse the pending connection request with a reason; keep listening."""
        if self._pending_request is None or self._state is not State.LISTEN:
            raise LocalProtocolError("refuse() needs a pending ConnectionRequested in LISTEN")
        self._pending_request = None
        self._early_in = None  # refused: nothing delivered
        self._queue_error(reason)

    def send(self, data: bytes | bytearray | memoryview, now: float) -> int:
        """Queue application bytes; returns how many fit in the send buffer.

        Raises:
            LocalProtocolError: after ``send_eof``/``close``, or once the
                connection has ended.
        """
        if self._state not in WRITABLE:
            raise LocalProtocolError(f"cannot send: the connection is {self._state.value}")
        if self._sender.eof_requested:
            raise LocalProtocolError("cannot send after send_eof() or close()")
        return self._sender.queue_data(data)

    def send_eof(self, now: float) -> None:
        """Half-close: no more data from this side; the peer sees EOF after the last byte."""
        if self._state in TERMINAL:
            raise LocalProtocolError(f"cannot send EOF: the connection is {self._state.value}")
        self._sender.eof_requested = True

    def close(self, now: float, *, patience: float | None = None) -> None:
        """Graceful close of both directions (TCP's close()).

        Our EOF follows everything already queued; the close finishes
        (ConnectionClosed) when it is acknowledged and the peer's EOF has
        arrived.  Data not yet read is discarded, and *new* data from the peer
        after this point is refused: the connection is aborted with an E
        packet, as TCP answers with RST, so a peer that keeps writing learns
        that nobody reads.  Use :meth:`send_eof` to stop sending but keep
        receiving.

        The close takes as long as it makes progress: however much data is
        still queued, it never ends because a fixed time has passed.  It is
        given up (ConnectionAborted, an E packet to the peer) only after
        ``patience`` seconds (default ``dead_after``) in which nothing moved:
        no packet of ours newly acknowledged and nothing new in order from the
        peer.  Each such step re-arms the deadline (see :meth:`get_timer`).
        The default follows ``dead_after`` as the round trip is measured
        during the close: a close begun at the first answer, before the queue
        in front of the line showed in any round trip, must not keep that
        answer's few seconds.  A silent link is judged dead after
        ``dead_after`` as always."""
        if self._state not in WRITABLE:
            return
        if self._state is State.ESTABLISHED and self._close_deadline == math.inf:
            self._close_patience_given = patience
            self._close_patience = self._dead_after if patience is None else patience
            self._close_mark = self._progress_mark()
            self._close_progress_at = now
            self._close_deadline = now + self._close_patience
        self._sender.eof_requested = True
        self._receiver.discard = True
        self._receiver.discarded_total += len(self._receiver.readable)
        self._receiver.readable.clear()
        if allowed(self._state, Trigger.CLOSE):
            self._go(Trigger.CLOSE)

    def abort(self, reason: str, now: float) -> None:
        """End the connection at once, telling the peer why (an E packet)."""
        if self._state not in LIVE:
            return
        self._clock = max(self._clock, now)
        self._finish_abort(reason, by_peer=False, send=True)

    def reset(self) -> None:
        """After the connection ended, return to IDLE to listen or connect again.

        Statistics counters keep accumulating across connections.
        """
        self._go(Trigger.RESET)
        self._reset_connection()

    # -- public: the expedited lane -------------------------------------------------

    @property
    def expedited(self) -> bool:
        """Both ends agreed on the expedited lane (PROTOCOL.md section 11)."""
        return self._negotiated is not None and self._negotiated.expedited

    def send_expedited(self, message: bytes | bytearray | memoryview, now: float) -> None:
        """Send ``message`` ahead of every byte queued on the stream.

        The message travels in packets of its own, handed to the line before
        any paced data (behind only what the UART already holds), is
        retransmitted until acknowledged like data, and is delivered to the
        peer's :meth:`read_expedited` whole, exactly once, and in the order
        of ``send_expedited`` calls -- but *not* ordered with the stream: it
        overtakes bytes sent before it.  The stream's EOF and a graceful
        close wait for it.

        Raises:
            LocalProtocolError: the lane was not negotiated (:attr:`expedited`
                is False: the peer is a classic Kermit or an older telelink,
                or either side has ``EndpointConfig.expedited`` off), the
                connection is not established, or
                :data:`~serialsocket._expedited.EXPEDITED_QUEUE` messages
                already wait for the peer.
            ValueError: ``message`` is empty, longer than
                :data:`~serialsocket._expedited.EXPEDITED_MAX_BYTES`, or needs
                more than :data:`~serialsocket._expedited.EXPEDITED_WINDOW`
                packets at the negotiated packet length.
        """
        if self._state is not State.ESTABLISHED or not self.expedited:
            raise LocalProtocolError(
                "no expedited lane: the connection is "
                f"{self._state.value}{'' if self.expedited else ' without one negotiated'}; "
                "send it on the stream instead"
            )
        data = bytes(message)
        if not 0 < len(data) <= EXPEDITED_MAX_BYTES:
            raise ValueError(
                f"an expedited message is 1..{EXPEDITED_MAX_BYTES} bytes, not {len(data)}"
            )
        cut = self._encoding.encode_fields(data, self._capacity - 1, EXPEDITED_WINDOW + 1)
        if len(cut) > EXPEDITED_WINDOW or sum(used for _, used in cut) < len(data):
            raise ValueError(
                f"{len(data)} bytes need more than {EXPEDITED_WINDOW} packets at the "
                f"negotiated packet length ({self._capacity} data characters each); "
                "send less at once"
            )
        self._xsend.submit([f for f, _ in cut])

    def offer_expedited(self, message: bytes | bytearray | memoryview, now: float) -> bool:
        """:meth:`send_expedited`, except that a full lane returns False (nothing
        queued; offer again after an acknowledgement) instead of raising.
        What an I/O adapter's waiting send uses."""
        if self._state is State.ESTABLISHED and self.expedited and self._xsend.full:
            return False
        self.send_expedited(message, now)
        return True

    @property
    def expedited_over(self) -> str | None:
        """Why no further expedited message can arrive (None while one can):
        what an I/O adapter's waiting receive reports once the inbox is empty."""
        if self._state in TERMINAL:
            return f"the connection ended ({self._state.value}); no more expedited messages"
        return None

    def read_expedited(self) -> bytes | None:
        """The next expedited message from the peer, whole, or None."""
        return self._xrecv.read()

    @property
    def expedited_readable(self) -> int:
        """Expedited messages :meth:`read_expedited` would return now."""
        return len(self._xrecv.inbox)

    @property
    def expedited_settled(self) -> bool:
        """Every expedited message sent so far has been acknowledged."""
        return self._xsend.idle

    # -- public: the latest-value lane ------------------------------------------------

    @property
    def latest(self) -> bool:
        """Both ends agreed on the latest-value lane (PROTOCOL.md section 12)."""
        return self._negotiated is not None and self._negotiated.latest

    def send_latest(self, value: bytes | bytearray | memoryview, now: float) -> None:
        """Offer ``value`` as the newest of a series: it replaces a value not
        yet handed to the line, and once sent, a newer value replaces it on
        the line instead of its resend.

        A value goes to the line when the pacer has room after the stream's
        own packets (the stream keeps priority), in one packet of its own.
        The peer's :meth:`read_latest` gets values in the order they were
        sent, each at most once, possibly with gaps (the superseded ones);
        the newest value offered is resent until acknowledged, so once the
        offers stop the peer holds the last one.  A graceful close waits for
        that acknowledgement.

        Raises:
            LocalProtocolError: the lane was not negotiated (:attr:`latest`
                is False: a classic Kermit or an older telelink, or either
                side has ``EndpointConfig.latest`` or ``expedited`` off), or
                the connection is not established or is closing.
            ValueError: ``value`` is empty, longer than
                :data:`~serialsocket._latest.LATEST_MAX_BYTES`, or does not
                fit one packet at the negotiated length once encoded.
        """
        if self._state is not State.ESTABLISHED or not self.latest or self.closing:
            why = "closing" if self.closing else self._state.value
            raise LocalProtocolError(
                "no latest-value lane: the connection is "
                f"{why}{'' if self.latest else ' without one negotiated'}; "
                "send it on the stream instead"
            )
        data = bytes(value)
        if not 0 < len(data) <= LATEST_MAX_BYTES:
            raise ValueError(f"a latest value is 1..{LATEST_MAX_BYTES} bytes, not {len(data)}")
        cut = self._encoding.encode_fields(data, self._capacity - 1, 2)
        if len(cut) != 1 or cut[0][1] < len(data):
            raise ValueError(
                f"{len(data)} bytes do not fit one packet at the negotiated packet length "
                f"({self._capacity} data characters); send less, or use the stream"
            )
        self._lsend.offer(cut[0][0])

    def read_latest(self) -> bytes | None:
        """The newest value from the peer not yet read, or None.  A value that
        arrived while an older one was unread replaced it."""
        return self._lrecv.read()

    @property
    def latest_readable(self) -> bool:
        """:meth:`read_latest` would return a value now."""
        return self._lrecv.value is not None

    @property
    def latest_waiting(self) -> bool:
        """A value offered to :meth:`send_latest` has not yet been handed to the line."""
        return self._lsend.pending is not None

    @property
    def latest_settled(self) -> bool:
        """Nothing waits for the line and the newest value sent was acknowledged."""
        return self._lsend.idle

    @property
    def latest_over(self) -> str | None:
        """Why no further latest value can arrive (None while one can)."""
        if self._state in TERMINAL:
            return f"the connection ended ({self._state.value}); no more latest values"
        return None

    # -- public: data -------------------------------------------------------------

    def read(self, max_bytes: int | None = None, now: float | None = None) -> bytes:
        """Take received bytes (in order, each exactly once).

        Returns b"" when nothing is readable; check :attr:`at_eof` to tell EOF
        from "nothing yet".  Reading may reopen the advertised window; pass
        ``now`` so the window update can be sent at once.
        """
        out = self._receiver.read(max_bytes)
        if out and self._state is State.ESTABLISHED:
            grown = self._receiver.window_to_advertise() - self._receiver.advertised
            if grown >= max(1, self._receiver.window // 4) or (
                self._receiver.advertised == 0 and grown > 0
            ):
                self._queue_ack(self._receiver.last_in_order())
        return out

    @property
    def control_pending(self) -> int:
        """Control packets (ACK, NAK, E) queued for the next :meth:`data_to_send`.

        An I/O loop can compare it around :meth:`read` to learn whether the
        read queued a window update that its writer must send.
        """
        return len(self._control)

    @property
    def input_held(self) -> int:
        """Bytes :meth:`receive_data` holds: the start of a packet still arriving.

        An I/O loop can compare it around :meth:`receive_data`: when it grew
        by all the bytes fed, they completed no packet (and no rejection),
        so nothing else changed and nobody needs waking.
        """
        return self._parser.buffered

    @property
    def readable(self) -> int:
        """Bytes :meth:`read` would return now."""
        return len(self._receiver.readable)

    @property
    def closing(self) -> bool:
        """:meth:`close` was called and the close has not finished yet."""
        return self._state is State.ESTABLISHED and self._close_deadline < math.inf

    @property
    def data_settled(self) -> bool:
        """Every byte we were given is acknowledged and the peer's EOF has arrived.

        The data of both directions is complete, whatever then happens to the
        closing handshake (a last ACK of our EOF lost with the line is not data
        lost): what "delivered" means for a close (RELIABILITY.md section 1).
        """
        s = self._sender
        return (
            not s.queue
            and s.bytes_in_flight == 0
            and self._receiver.eof
            and self._xsend.idle
            and self._lsend.idle
        )

    @property
    def at_eof(self) -> bool:
        """The peer's EOF has been delivered and every byte before it read."""
        return self._receiver.eof and not self._receiver.readable

    @property
    def send_buffer_free(self) -> int:
        """Bytes :meth:`send` would accept now."""
        return self._sender.free()

    @property
    def all_acknowledged(self) -> bool:
        """Everything queued so far has been sent and acknowledged."""
        s = self._sender
        return not s.queue and s.base == s.next and self._xsend.idle and self._lsend.idle

    # -- public: the I/O side ---------------------------------------------------------

    def receive_data(self, data: bytes | bytearray | memoryview, now: float) -> None:
        """Feed bytes read from the line."""
        counters = self._counters
        counters["wire_bytes_received"] += len(data)
        parser = self._parser
        parser.receive_data(data)
        try:
            self._receive_events(parser, counters, now)
        finally:
            # The data fields of this read, decoded together (Receiver.take_fields).
            if self._receiver.pending:
                self._receiver.flush()

    def _receive_events(self, parser: PacketParser, counters: dict[str, int], now: float) -> None:
        """Handle the packets and rejections :meth:`receive_data` parsed."""
        while (event := parser.next_event()) is not None:
            if isinstance(event, PacketReceived):
                counters["packets_received"] += 1
                self._last_heard = now
                try:
                    self._on_packet(event.packet, now)
                except RemoteProtocolError as exc:
                    log.warning("protocol error from peer: %s", exc)
                    self._finish_abort(exc.error_hint, by_peer=False, send=True)
                if self._close_deadline != math.inf:
                    self._note_close_progress(now)
            elif event.reason in _DAMAGE and self._state is _ESTABLISHED:
                if event.damaged is not None:
                    self._damaged.append(event.damaged)  # a repair packet may mend it
                nak = self._receiver.gap_to_nak(now, self._rtt.timeout())
                if nak is not None:
                    self._queue_nak(nak)
            if self._state is not _ESTABLISHED and self._state in DEAF:
                break

    def data_to_send(self, now: float) -> bytes:
        """Bytes to write to the line now (control first, then paced data).

        With :attr:`line_discards`, call :meth:`take_discard` after each call
        and before writing what it returned."""
        out: list[bytes] = []
        queued_until = self._pacer.free_at
        control_until = self._control_done_at
        self._emit_control(now, out)
        if self._state is State.ESTABLISHED and self._negotiated is not None:
            cut = False
            if queued_until is not None and self._preempt_due(queued_until, now):
                self._preempt(queued_until, now)
                cut = True
            self._release_expedited(now, out)
            if cut and control_until > now:
                # Our last ACK may have been among the bytes dropped.
                self._queue_ack(self._receiver.last_in_order())
                self._emit_control(now, out)
            self._release_data(now, out)
            self._release_latest(now, out)
        elif self._state is State.CONNECTING and self._flight is not None:
            self._release_flight(now, out)
        return b"".join(out)

    def _emit_control(self, now: float, out: list[bytes]) -> None:
        """Queued ACKs, NAKs and E packets go first, and the time the last
        of them leaves the UART is kept (a drop may cut it: _preempt)."""
        for wire in self._control:
            out.append(wire)
            self._control_done_at = self._account(wire, now)
        self._control.clear()

    def take_discard(self) -> bool:
        """Whether the port must drop what it holds unsent before the bytes
        the last :meth:`data_to_send` returned are written (an expedited
        packet cuts in: PROTOCOL.md 11); True once per such call.  Only with
        :attr:`line_discards`; the endpoint has already arranged to resend
        whatever the drop may cut."""
        due, self._discard_due = self._discard_due, False
        return due

    def get_timer(self) -> float | None:
        """When :meth:`handle_timer` must next be called, or None."""
        match self._state:
            case State.CONNECTING:
                return min(self._init_deadline, self._connect_deadline)
            case State.LINGER:
                return self._linger_until
            case State.ESTABLISHED:
                times = [self._last_heard + self._dead_after, self._next_probe_time()]
                if self._close_deadline < math.inf:
                    times.append(self._close_deadline)
                for deadline in (
                    self._sender.next_deadline(),
                    self._xsend.next_deadline(),
                    self._lsend.next_deadline(),
                ):
                    if deadline is not None:
                        times.append(deadline)
                return min(times)
            case _:
                return None

    def get_send_timer(self) -> float | None:
        """When :meth:`data_to_send` will next release paced data, or None.

        Separate from :meth:`get_timer` because it concerns the writer, not the
        protocol: an I/O loop whose writer is blocked on a slow port must not
        spin on it.  None when nothing waits, when the window is shut, or when
        the line rate is unknown (then data is released as soon as it may be).
        """
        if self._state is State.CONNECTING and self._flight is not None:
            s, flight = self._sender, self._flight
            if s.next <= flight.packets and s.queue:
                return self._pacer.wake()
            return None
        if self._state is not State.ESTABLISHED:
            return None
        return self._pacing_wake()

    def handle_timer(self, now: float) -> None:
        """Run whatever timers are due at ``now`` (safe to call early)."""
        match self._state:
            case State.CONNECTING:
                self._connecting_timer(now)
            case State.LINGER:
                if now >= self._linger_until:
                    self._go(Trigger.LINGER_EXPIRED)
            case State.ESTABLISHED:
                self._established_timer(now)

    def events(self) -> list[Event]:
        """Take all pending events."""
        out = list(self._events)
        self._events.clear()
        return out

    def next_event(self) -> Event | None:
        """Take the next pending event, or None."""
        return self._events.popleft() if self._events else None

    @property
    def dead_after(self) -> float:
        """Seconds of silence after which the link is judged dead: configured
        (``dead_after``), or derived from the measured round trip once there
        is one (from the hints before).  A close that makes no progress for
        this long is given up."""
        return self._dead_after

    def statistics(self) -> EndpointStatistics:
        """A snapshot of counters, sequence variables and timers."""
        s, r, c = self._sender, self._receiver, self._counters
        ps = self._parser.statistics()
        return EndpointStatistics(
            state=self._state.value,
            send_next=s.next,
            send_base=s.base,
            receive_expected=r.expected,
            window=s.window,
            effective_window=self._effective_window(),
            peer_window=s.peer_window,
            in_flight=s.in_flight(),
            retransmit_queue=s.retransmit_pending(),
            packets_sent=c["packets_sent"],
            packets_received=c["packets_received"],
            wire_bytes_sent=c["wire_bytes_sent"],
            wire_bytes_received=c["wire_bytes_received"],
            bytes_queued=len(s.queue),
            bytes_acknowledged=s.bytes_acked,
            bytes_in_flight=s.bytes_in_flight,
            bytes_delivered=r.delivered_total,
            bytes_readable=len(r.readable),
            eof_received=r.eof,
            retransmissions=c["retransmissions"],
            timeouts=c["timeouts"],
            fast_retransmits=c["fast_retransmits"],
            naks_sent=c["naks_sent"],
            naks_received=c["naks_received"],
            duplicates_received=c["duplicates_received"],
            out_of_window=c["out_of_window"],
            dropped_buffer_full=c["dropped_buffer_full"],
            ignored_packets=c["ignored_packets"],
            check_failures=ps.rejected.get(RejectReason.BAD_CHECK.value, 0),
            rejected=sum(ps.rejected.values()),
            resyncs=ps.resyncs,
            garbage_bytes=ps.garbage_bytes,
            smoothed_rtt=self._rtt.srtt,
            timeout=self._rtt.timeout(),
            line_backlog=self._pacer.backlog(self._clock),
            rtt_variation=self._rtt.rttvar,
            base_rtt=self._rate.base_rtt,
            line_rate=self._bits(self._rate.rate),
            measured_rate=self._bits(self._rate.measured),
            queue_delay=self._rate.queue_delay,
            long_sequence=self._long_seq,
            receive_buffer=r.receive_buffer,
            buffer_capped=self._buffer_capped,
            expedited=self.expedited,
            expedited_sent=self._xsend.messages_sent,
            expedited_received=self._xrecv.messages_received,
            expedited_unacknowledged=len(self._xsend.outstanding) + len(self._xsend.waiting),
            expedited_refused=self._xrecv.refused,
            latest=self.latest,
            latest_offered=self._lsend.offered,
            latest_coalesced=self._lsend.coalesced,
            latest_sent=self._lsend.sent_values,
            latest_resent=self._lsend.resent,
            latest_received=self._lrecv.received,
            latest_superseded=self._lrecv.superseded,
            idle_copies=c["idle_copies"],
            doubled_resends=c["doubled_resends"],
            preemptions=c["preemptions"],
            preempted_resends=c["preempted_resends"],
            packet_length=self._length.length,
            byte_error_rate=self._length.byte_error_rate,
            early_sent=len(self._early or b""),
            early_delivered=c["early_delivered"],
            early_received=c["early_received"],
            flight_announced=self._flight.packets if self._flight is not None else 0,
            flight_packets=c["flight_packets"],
            flight_refused=c["flight_refused"],
            flight_received=c["flight_received"],
            correction=self._parser.correction,
            corrected_sent=c["corrected_sent"],
            repaired=ps.repaired + c["repairs_applied"],
            repairs_sent=c["repairs_sent"],
            repairs_failed=c["repairs_failed"],
            duplicate_acks_held=c["duplicate_acks_held"],
        )

    # -- internals: connection ------------------------------------------------------

    def _reset_connection(self) -> None:
        cfg = self.config
        self._negotiated = None
        self._pending_request = None
        self._sender = Sender(send_buffer=cfg.derived_send_buffer())
        self._receiver = Receiver(
            receive_buffer=cfg.receive_buffer,
            window=cfg.window,
            capacity=data_capacity(self._max_length, cfg.check),
        )
        self._control = []
        self._events = deque()
        self._parser.reset()
        self._parser.check = BlockCheck.CRC16
        self._parser.correction = False
        self._damaged: deque[bytes] = deque(maxlen=DAMAGED_KEPT)
        self._parser.max_length = self._max_length
        self._send_check = BlockCheck.CRC16
        self._encoding = PRINTABLE
        self._capacity = 0
        self._adaptive = cfg.max_packet_length is None
        self._length = LengthChooser(self._start_length)
        self._correction = False
        self._peer_length = self._start_length
        self._mean_wire = float(self._start_length + 1)
        self._pacer.reset()
        self._rate = RateEstimator(self._rate_hint())
        self._pacer.paced = self._rate.rate is not None
        self._pacer.tight = self._rate.rate is not None
        self._pair: tuple[Outstanding, Outstanding] | None = None
        self._pair_lead_acked: float | None = None
        self._pair_settled: float | None = None
        self._last_first: tuple[Outstanding, float] | None = None
        self._control_done_at = -math.inf
        self._acked_at: dict[int, float] = {}
        self._preempted: set[int] = set()
        self._uncut_until = -math.inf
        self._discard_due = False
        self._clock = 0.0
        self._pacer.probe = self._pair_due()
        self._last_heard = 0.0
        self._last_probe = -math.inf
        self._last_data_at = None
        self._data_gap = 0.0
        self._init_deadline = math.inf
        self._connect_deadline = math.inf
        self._linger_until = math.inf
        self._answer_span = 0.0
        self._peer_timeout = 0.0
        self._dead_after = self._liveness()
        self._rtt.ceiling = self._ceiling()
        self._close_deadline = math.inf
        self._close_patience = self._dead_after
        self._close_patience_given = None
        self._close_progress_at = 0.0
        self._close_mark = (0, 0)
        self._peer_data_seen = False
        self._abort_reason = None
        self._error_sent_at = -math.inf
        self._init_sent_at = 0.0
        self._first_init_at = 0.0
        self._init_transmissions = 0
        self._early = None
        self._early_chars = 0
        self._early_in = None
        self._flight = None
        self._flight_bytes = bytearray()
        self._flight_in = None
        self._flight_taken = False
        self._flight_data_seen = False
        self._flight_floor = 0.0
        self._flight_ahead = 0
        self._flight_past = 0
        self._flight_wire = 0
        self._init_chars = 0
        self._answer_chars = 0
        self._accepted_init = None
        self._answer_sent_at = 0.0
        self._answers = 0
        self._window_key = None
        self._backlog_at = -math.inf
        self._window_cached = 1
        self._long_seq = False
        self._buffer_capped = False
        self._tune_at = -math.inf
        self._tune_taken = 0
        self._answer_with = None
        self._xsend = ExpeditedSender()
        self._xrecv = ExpeditedReceiver()
        self._lsend = LatestSender()
        self._lrecv = LatestReceiver()

    def _go(self, trigger: Trigger) -> None:
        old = self._state
        self._state = transition(old, trigger)
        log.debug("state %s -> %s (%s)", old.value, self._state.value, trigger.value)

    def _send_init(self, now: float) -> None:
        if self._early is None:
            # Fixed at the first copy: every resend carries the same bytes,
            # which stay at the head of the send queue until the answer.
            # What the init can carry goes in it (a command: it arrives with
            # the request).  More than that goes in a first flight right
            # behind the init, densely encoded, and then none in the init:
            # early data would only lengthen it (and its resends) with the
            # same bytes in the classic encoding, 0.9 s of an 8 KiB transfer
            # at 2400 bit/s and 1.3 s (PROTOCOL.md 14).
            self._early = self._early_bytes()
            if len(self._sender.queue) > len(self._early):
                self._flight = self._plan_flight(now)
                if self._flight is not None:
                    self._early = b""
            self._early_chars = len(EARLY_ENCODING.encode(self._early)) + 2 if self._early else 0
        mine = self._mine.with_early(self._early).with_flight(self._flight)
        init = Packet(seq=0, type=PacketType.INIT, data=mine.encode())
        wire = build_packet(init, BlockCheck.CRC16)
        self._init_chars = len(wire)
        self._control.append(wire)
        if self._init_transmissions == 0:
            self._first_init_at = now
        self._init_sent_at = now
        self._init_transmissions += 1
        # The timeout covers a full packet; a longer init takes longer to send.
        wait = self._rtt.timeout() + self._init_extra_time()
        cfg = self.config
        if cfg.line_rate is None and cfg.one_way_delay == 0:
            # Nothing says how slow the line is: resends 50 ms apart (the
            # derived timeout) piled eight inits, 26 s of them, on a 300 bit/s
            # line before the first answer, and the listener answered each.
            # RFC 6298's initial 1 s, doubled per resend, costs a fast line
            # nothing unless its first init is lost.
            wait = max(wait, UNHINTED_INIT_TIMEOUT * 2 ** (self._init_transmissions - 1))
        self._init_deadline = now + wait

    def _plan_flight(self, now: float) -> Flight | None:
        """The first flight to announce in our first init, or None
        (PROTOCOL.md 14), and the sending side set up to cut it.

        Only with more bytes queued than early data takes, the XLANES field
        going out and ``first_flight`` on; then no early data goes.  Its
        packets are cut as the agreement of our own offer with itself says
        (:func:`self_agreement`); together they take at most what
        :data:`FIRST_FLIGHT_RATE` carries in :data:`FLIGHT_SECONDS`, and
        on a slower hinted line that line's second, or its round trip if
        longer (within the same bound)."""
        cfg = self.config
        if not cfg.first_flight or self._mine.lanes is None or not self._sender.queue:
            return None
        assumed = self_agreement(self._mine)
        length = self._start_length
        if self._adaptive:
            # Twice the starting length (at most ``max_packet_time`` of the
            # hinted line): nothing is measured yet, and the queue the flight
            # builds delays the ACKs that earn longer packets.  Measured on
            # the real-time table's lines (virtual replica): 128 characters
            # left a clean 2400 bit/s line at 0.929 of the line against
            # 0.934 without a flight; 256, 0.935 (and 0.850 at 1.3 s one way,
            # from 0.792), while 1e-3 still gained.
            cap = cfg.measured_length_cap(assumed.send_max_length, self._rate_hint())
            length = max(length, min(FLIGHT_LENGTH_FACTOR * length, cap))
        length = min(length, assumed.send_max_length, MAX_FLIGHT_LENGTH)
        # At most what the unhinted flight takes whatever the hints say: a
        # rate hint ten times high, trusted, queued 27 s of a 2400 bit/s
        # line before any answer, timed as if it took 2.7.
        chars = FIRST_FLIGHT_RATE * FLIGHT_SECONDS
        if cfg.line_rate is not None:
            # A slower hinted line: its own second, or the round trip.
            per_second = cfg.line_rate / cfg.bits_per_char
            chars = min(chars, per_second * max(FLIGHT_SECONDS, 2 * cfg.one_way_delay))
        packets = math.ceil(chars / (length + 1))
        packets = max(1, min(packets, MAX_FLIGHT_PACKETS, assumed.window))
        self._configure_send(assumed)
        self._sender.window = self._sender.peer_window = packets
        # Its packets are the first the rate estimator sees (the init is
        # the first delivery point; the first two are a rate pair), as the
        # first packets after the answer are without a flight.
        self._rate.start(now, None)
        # Tells a resent request from a restarted connector's (PROTOCOL.md 14).
        self._connects += 1
        nonce = (int(now * 1000) + 2731 * self._connects) & 4095
        return Flight(packets=packets, length=length, nonce=nonce)

    def _init_extra_time(self) -> float:
        """Seconds the early data adds to the init on the line (0 with none,
        or with the rate unknown)."""
        if not self._early:
            return 0.0
        extra = len(EARLY_ENCODING.encode(self._early)) + 2
        return self.config.transmit_time(extra)

    def _early_bytes(self) -> bytes:
        """The head of the send queue that fits in the init (PROTOCOL.md 13).

        At most ``early_data`` bytes in an init of at most EARLY_INIT_LIMIT
        characters, and early data lengthens the init by no more than half a
        full packet, or 0.5 % of the round trip with the line's rate and
        delay given, whichever is more.  The init's answer is the rate
        estimator's reference round trip, which allows one packet's transmit
        time plus jitter (up to 1 % of the path) for error
        (serialsocket._rate ``fast_evidence``); early data may use half of
        that.  A reference longer made every data sample look early and the
        pacer ramped past the line: 90 timeouts in a 26 KB transfer at
        2400 bit/s and 1.3 s with 455 characters of early data; 3 times the
        line at 9600 bit/s and 0.27 s with one packet's worth."""
        queue, limit = self._sender.queue, self.config.early_data
        if not queue or not limit or self._mine.lanes is None:
            return b""
        take = bytes(queue[:limit])
        cfg = self.config
        allowed = self._start_length // 2
        if cfg.line_rate is not None:
            per_second = cfg.line_rate / cfg.bits_per_char
            allowed = max(allowed, int(0.005 * 2 * cfg.one_way_delay * per_second))
        # What the init may hold besides its own fields, header and check.
        room = min(EARLY_INIT_LIMIT - len(self._mine.encode()) - 2 - 7 - 3, allowed - 2)
        while take and len(EARLY_ENCODING.encode(take)) > room:
            take = take[: len(take) * max(room, 0) // len(EARLY_ENCODING.encode(take))]
        return take

    def _on_init(self, packet: Packet, now: float) -> None:
        st = self._state
        if st is State.LINGER:
            # The peer has moved on to a new connection: our last ACK arrived.
            self._go(Trigger.LINGER_EXPIRED)
            return
        if st is State.ESTABLISHED:
            if self._peer_data_seen or (
                self._flight_data_seen and bytes(packet.data) != self._accepted_init
            ):
                # (After first-flight data only, a request that is not the
                # one we answered -- another nonce -- is a restarted
                # connector's: PROTOCOL.md 14.)
                self._finish_abort(
                    "peer restarted: new connection request on a live link",
                    by_peer=True,
                    send=False,
                )
            else:
                self._answers += 1  # a second answer: the seed is only an upper bound
                self._answer_init()  # Our answer was lost; say it again.
                # Another copy after our answer: the round trip is longer than
                # the time since our first answer; the silence verdict must
                # wait for longer than that (see _liveness).
                self._answer_span = now - self._answer_sent_at
                self._dead_after = self._liveness()
            return
        if not allowed(st, Trigger.INIT_RECEIVED):
            return
        try:
            theirs = InitParameters.decode(packet.data)
            if self._rtt.srtt is None and theirs.timeout_hint:
                # The connector's patience bounds ours from below until we
                # measure the round trip (see _peer_patience).
                self._peer_timeout = theirs.timeout_hint
                self._dead_after = self._liveness()
                self._rtt.ceiling = self._ceiling()
            mine = self._mine
            if st is State.LISTEN:
                # The connector judged that its line needs more than 31
                # packets in flight: agree if we may (a listener often has no
                # hints of its own).  Not in a simultaneous open, where both
                # inits are already out and each side must negotiate the
                # same two offers.  answer() also echoes the XCAPAS
                # features both know, and nothing to a request without XCAPAS.
                mine = mine.answer(theirs, self._long_offer())
            agreed = negotiate(mine, theirs)
            self._early_in = None
            early_taken = bool(
                st is State.LISTEN and theirs.early and (mine.lanes or 0) & LANE_EARLY
            )
            if early_taken:
                # Taken: delivered when the connection is (the answer says so).
                self._early_in = theirs.early
                self._answer_with = mine
            else:
                # Not taken (none sent, refused by configuration, or a
                # simultaneous open): the answer says nothing was delivered,
                # and the connector sends those bytes as ordinary data.
                self._answer_with = mine.without_early()
            self._flight_in = theirs.flight
            self._flight_taken = self._takes_flight(st, mine, theirs, agreed, early_taken)
            if self._flight_taken and self._answer_with.lanes is not None:
                # (Clear otherwise: our own lanes never carry the bit.)
                self._answer_with = replace(
                    self._answer_with, lanes=self._answer_with.lanes | LANE_FLIGHT
                )
            self._accepted_init = bytes(packet.data)
        except RemoteProtocolError as exc:
            log.info("refusing connection: %s", exc)
            self._queue_error(exc.error_hint)
            if st is State.CONNECTING:
                self._finish_abort(exc.error_hint, by_peer=False, send=False)
            return
        if st is State.LISTEN and not self.config.auto_accept:
            if self._pending_request is None:
                self._pending_request = agreed
                self._events.append(ConnectionRequested(parameters=agreed))
            return
        self._establish(agreed, now, answer=True)

    def _takes_flight(
        self,
        state: State,
        mine: InitParameters,
        theirs: InitParameters,
        agreed: Negotiated,
        early_taken: bool,
    ) -> bool:
        """Whether we take the first flight ``theirs`` announces (PROTOCOL.md
        14): we take flights, answer at once (a request the application must
        accept first has its flight's packets dropped meanwhile), took its
        early data if it has any (the flight's bytes follow them), and the
        agreement reads its packets as they were cut: the same block check,
        data encoding and sequence numbers as the request's agreement with
        itself, a window that holds it, packets no longer than we accept."""
        flight = theirs.flight
        if (
            flight is None
            or state is not State.LISTEN
            or not self.config.takes_first_flight
            or mine.lanes is None  # (our answer could not say it was taken)
            or not self.config.auto_accept
            or (theirs.early and not early_taken)
        ):
            return False
        try:
            assumed = self_agreement(theirs)
        except RemoteProtocolError:
            return False
        return (
            flight_format(assumed) == flight_format(agreed)
            and agreed.window >= flight.packets
            and agreed.receive_max_length >= flight.length
        )

    def _on_init_answer(self, packet: Packet, now: float) -> None:
        if not allowed(self._state, Trigger.INIT_ACKED):
            return
        try:
            theirs = InitParameters.decode(packet.data)
            agreed = negotiate(self._mine, theirs)
        except RemoteProtocolError as exc:
            self._finish_abort(exc.error_hint, by_peer=False, send=True)
            return
        self._answer_chars = len(packet.data) + 7  # MARK..TYPE, CRC-16, CR
        taken = self._flight is not None and bool((theirs.lanes or 0) & LANE_FLIGHT)
        if taken and flight_format(agreed) != flight_format(self_agreement(self._mine)):
            # Taken, its packets would be read in a format they were not
            # cut in: a listener that breaks PROTOCOL.md 14.
            self._finish_abort("Bad init answer: first flight taken", by_peer=False, send=True)
            return
        if self._flight is not None and not taken:
            self._unwind_flight(self._flight)
        if self._early and (theirs.lanes or 0) & LANE_EARLY:
            # The listener delivered our early data: it is not sent again.
            del self._sender.queue[: len(self._early)]
            self._sender.bytes_acked += len(self._early)
            self._counters["early_delivered"] += len(self._early)
        if self._init_transmissions == 1:
            # The init went out once: its answer is a valid RTT sample (Karn).
            # Early data made it longer by at most what the rate estimator's
            # reference allows for (see _early_bytes).
            self._rtt.sample(now - self._init_sent_at)
            self._measured()
        else:
            # Which copy was answered is unknown, but not the first one's
            # departure: the round trip is at most the time since.  Too long
            # rather than too short: without it nothing is measured until a
            # data packet sent once is acknowledged, and with no hints the
            # 60 s unmeasured dead_after ended every link whose round trip
            # is longer (60 s one way: aborted with nothing delivered).
            self._rtt.seed(now - self._first_init_at)
            self._measured()
        self._establish(agreed, now, answer=False, flight_taken=taken)

    def _establish(
        self, agreed: Negotiated, now: float, *, answer: bool, flight_taken: bool = False
    ) -> None:
        self._negotiated = agreed
        self._pending_request = None
        self._go(
            Trigger.INIT_ACKED
            if self._state is State.CONNECTING and not answer
            else Trigger.INIT_RECEIVED
        )
        # Our first flight (PROTOCOL.md 14): taken, it is data of this
        # connection, cut by the format just agreed; else its bytes go again
        # after it, numbered from the announcement's bound on.
        flown = self._flight is not None and self._sender.next > 1
        taken = self._flight is not None and flight_taken and not answer
        if self._flight is not None and answer:
            # A simultaneous open: neither side takes the other's flight
            # (_on_init_answer unwinds a connector's that was not taken).
            self._unwind_flight(self._flight)
        self._parser.check = agreed.check
        self._parser.correction = agreed.correction
        self._configure_send(agreed, keep_length=taken and flown)
        self._receiver.modulus = agreed.modulus
        self._receiver.window = agreed.window
        if answer and self._flight_in is not None and not self._flight_taken:
            # The connector's flight was not taken: its packets are before
            # the window (acknowledged as old, never delivered), and its
            # data starts again after the announcement's bound.
            self._receiver.expected = self._flight_in.packets + 1
        self._size_receive_buffer()
        self._peer_length = min(self._start_length, agreed.receive_max_length)
        self._fit_receive_window()
        self._last_heard = now
        self._init_deadline = math.inf
        base = self._rtt.srtt if self._init_transmissions == 1 else None
        if self._flight is not None and not answer:
            # (Started at the init: _plan_flight.)
            self._rate.answered(base, self._init_chars * self._init_transmissions)
        else:
            self._rate.start(now, base)
        if not answer and self._init_transmissions > 1:
            # A resent init's answer bounds the round trip from above only:
            # the reference that judges later samples plausible, tightened
            # before it is trusted.  Without one every sample passed, and a
            # 0.02 s "round trip" on a 1.3 s line (an ACK timed from a pacer
            # model running late) made the link dead after 2 s of silence.
            self._rate.seed_base(now - self._first_init_at, trusted_later=False)
        if self._flight_wire:
            self._time_flight(now, taken=taken)
        self._flight_bytes.clear()
        if answer:
            self._answer_sent_at = now
            self._answers = 1
            self._answer_init()
        self._events.append(Connected(parameters=agreed))
        if answer and self._early_in:
            # Early data comes before any data packet (PROTOCOL.md 13).
            self._receiver.deliver(self._early_in)
            self._counters["early_received"] += len(self._early_in)
            self._early_in = None

    def _configure_send(self, agreed: Negotiated, *, keep_length: bool = False) -> None:
        """Cut and number data packets as ``agreed`` says (at establishment,
        and for a first flight before it: PROTOCOL.md 14)."""
        self._send_check = agreed.check
        self._encoding = agreed.encoding
        # The lanes' messages keep the starting length's fragments: their size
        # limit must not move with the measured data length.
        self._capacity = data_capacity(
            min(agreed.send_max_length, self._start_length), agreed.check
        )
        self._long_seq = agreed.long_seq
        self._sender.modulus = agreed.modulus
        self._sender.window = agreed.window
        self._sender.peer_window = agreed.window
        if not keep_length:
            # (A flight taken keeps what its packets showed of the line.)
            self._length = LengthChooser(min(self._start_length, agreed.send_max_length))
            if not self._adaptive:
                self._length.length = agreed.send_max_length
        self._length.check_length = int(agreed.check)
        self._correction = agreed.correction
        self._length_changed()

    def _time_flight(self, now: float, *, taken: bool) -> None:
        """Our first flight is out: with the line's rate unknown its packets
        wait in the UART's queue for as long as the line takes (an unpaced
        sender hands them at once), taken or not.  Until a rate is measured,
        every timer allows the slowest rate the init exchange permits (its
        packets crossed in the time since the first init): a flight packet's
        its place in the queue, and a packet sent after the answer all that
        is unacknowledged ahead of it, and the flight if it was not taken
        (:meth:`_queue_allowance`).  Without this, 3 packets of 384
        characters at 2400 bit/s timed out while still queued, the resends
        joined the queue, and no round trip or rate pair was ever measured:
        a storm (153 timeouts in an 8 KiB transfer behind a flight not
        taken).  Too long a timer costs only a repair a later packet's ACK
        or the receiver's NAK does not make first."""
        span = max(now - self._first_init_at, TIME_EPSILON)
        self._flight_floor = (self._init_chars + self._answer_chars) / span
        self._flight_ahead = 0 if taken else self._flight_wire
        self._flight_past = self._sender.next
        if taken:
            timeout = self._rtt.timeout()
            queued = 0
            for seq in sorted(self._sender.outstanding):
                pkt = self._sender.outstanding[seq]
                queued += len(pkt.wire)
                if not pkt.acked and pkt.deadline is not None:
                    self._sender.arm(pkt, now + timeout + queued / self._flight_floor)

    def _queue_allowance(self) -> float:
        """Seconds a packet handed now may wait behind what is ahead of it
        in the UART, while a first flight's queue is unmeasured (else 0)."""
        if not self._flight_floor:
            return 0.0
        ahead = self._flight_ahead + sum(
            len(p.wire) for p in self._sender.outstanding.values() if not p.acked
        )
        return ahead / self._flight_floor

    def _unwind_flight(self, flight: Flight) -> None:
        """Our first flight was not taken: its bytes go back to the head of
        the send queue, and numbering starts again after the announcement's
        bound."""
        s = self._sender
        sent = s.next - 1
        s.queue[:0] = self._flight_bytes
        self._flight_bytes.clear()
        s.restart_at(flight.packets + 1)
        # A rate pair among them would never be answered, and no other
        # pair would go (_pair_due): the rate stayed unmeasured, and at an
        # unknown rate the packets sent after timed out in a storm.
        self._pair = None
        self._last_first = None
        self._pair_lead_acked = None
        self._counters["flight_refused"] += sent
        self._mean_wire = float(self._start_length + 1)

    def _answer_init(self) -> None:
        self._control.append(
            build_packet(
                Packet(seq=0, type=PacketType.ACK, data=(self._answer_with or self._mine).encode()),
                BlockCheck.CRC16,
            )
        )

    def _queue_error(self, reason: str) -> None:
        text = PRINTABLE.encode(reason.encode("utf-8", "replace")[:_ERROR_TEXT_MAX])
        self._control.append(
            build_packet(Packet(seq=0, type=PacketType.ERROR, data=text), self._send_check)
        )

    def _finish_abort(self, reason: str, *, by_peer: bool, send: bool) -> None:
        established = self._state in CONNECTED
        if send:
            self._queue_error(reason)
            self._abort_reason = reason
            self._error_sent_at = self._clock
            free_at = self._pacer.free_at
            if self.line_discards and free_at is not None and free_at - self._clock > PREEMPT_AFTER:
                # Nothing the UART holds matters any more: the E cuts in as
                # an expedited packet does (PROTOCOL.md 11), so the peer
                # hears "aborted" a one-way delay later, not behind a queue.
                self._discard_due = True
                self._counters["preemptions"] += 1
        self._go(Trigger.REFUSED if self._state is State.CONNECTING else Trigger.ABORT)
        self._events.append(
            ConnectionAborted(reason=reason, by_peer=by_peer, refused=not established and by_peer)
        )

    def _declare_dead(self, silence: float) -> None:
        """Only from :meth:`_established_timer`: the table's one LINK_DEAD edge."""
        s = self._sender
        self._events.append(
            LinkDead(
                silence=silence,
                bytes_acknowledged=s.bytes_acked,
                bytes_in_flight=s.bytes_in_flight,
                bytes_unsent=s.unsent_bytes(),
            )
        )
        self._go(Trigger.LINK_DEAD)

    # -- internals: packets in ------------------------------------------------------

    def _on_packet(self, packet: Packet, now: float) -> None:
        ptype = packet.type
        state = self._state
        if state is _FAILED:
            if (
                ptype != _T_ERROR
                and self._abort_reason is not None
                and now - self._error_sent_at >= self._rtt.timeout()
            ):
                # The peer still talks: our E was lost.  Repeat it, once per timeout.
                self._error_sent_at = now
                self._queue_error(self._abort_reason)
            return
        if (
            self._answers >= 1
            and self._rtt.srtt is None
            and state is _ESTABLISHED
            and ptype != _T_INIT
            and not self._in_flight_in(packet)
        ):
            # The first packet the connector sent after our first answer: the
            # round trip is at most this (the connector may have waited, or
            # been answered by a later copy of our answer).  Seeding only
            # after a single answer left a listener whose connector had
            # resent its init (no hints, a long line) unmeasured, and its
            # 60 s unmeasured dead_after ended a healthy link at 60 s one way.
            self._rtt.seed(now - self._answer_sent_at)
            if self._answers == 1:
                self._rate.seed_base(now - self._answer_sent_at)
            self._measured()
        if ptype in (_T_DATA, _T_EOF):
            # Data first: once per packet of a transfer (then its ACK, below).
            # (ESTABLISHED is CONNECTED: tested first, as a frozenset lookup
            # hashes the enum member in Python.)
            connected = self._state is _ESTABLISHED or self._state in CONNECTED
            if connected and self._in_flight_in(packet):
                self._flight_data_seen = True
                self._counters["flight_received"] += 1
            elif connected:
                self._peer_data_seen = True
            if connected and (split := self._split_seq(packet)) is not None:
                if split[1]:
                    # Data spaces the ACKs behind it by the peer's line.  An
                    # empty EOF is no longer than an ACK: a netcat listener
                    # with nothing to send resends its EOF while the ACK
                    # waits behind our queue, and counting each copy voided
                    # every rate sample (no hints: never measured).
                    self._rate.reverse(now)
                self._on_data(split[0], split[1], ptype == _T_EOF, now)
        elif ptype == REPAIR_TYPE and self._correction:
            if self._state is _ESTABLISHED or self._state in CONNECTED:
                self._on_repair(packet, now)
        elif ptype == _T_ACK:
            if len(packet.data) >= _INIT_MIN_FIELD:
                self._on_init_answer(packet, now)
            elif (self._state is _ESTABLISHED or self._state in CONNECTED) and (
                split := self._split_seq(packet)
            ) is not None:
                self._on_ack(split[0], split[1], now)
        elif ptype == _T_INIT:
            self._on_init(packet, now)
        elif ptype == _T_ERROR:
            if self._state in PEER_MAY_ABORT:
                reason = self._safe_text(packet.data)
                self._finish_abort(reason, by_peer=True, send=False)
        elif ptype == _T_NAK:
            if self._state is State.ESTABLISHED and (split := self._split_seq(packet)) is not None:
                self._counters["naks_received"] += 1
                acked = self._sender.packets_acked
                horizon = self._nak_horizon()
                # A packet sent once has no earlier copy for the NAK to be
                # about; with repairs agreed its first resend is a repair
                # packet (15.6), 15-30 characters even if the NAK came early.
                # (Judged by our model of the line, whose rate runs late, a
                # NAK for the last packet of a transfer was set aside and
                # the repair waited 1.6 s for the next ACK.)
                self._sender.on_nak(
                    split[0], now, horizon, first_min_rtt=0.0 if self._correction else None
                )
                self._take_samples(now)
                if self._sender.packets_acked > acked:  # stop-and-wait NAK(n+1) = ACK(n)
                    self._rtt.on_progress()
        elif ptype in (URGENT, URGENT_ACK) and self.expedited and self._state in CONNECTED:
            if ptype == URGENT:
                self._rate.reverse(now)
                self._on_urgent(packet)
            else:
                self._on_urgent_ack(packet, now)
        elif ptype in (LATEST, LATEST_ACK) and self.latest and self._state in CONNECTED:
            if ptype == LATEST:
                self._rate.reverse(now)
                self._on_latest(packet)
            else:
                self._on_latest_ack(packet, now)
        else:
            self._counters["ignored_packets"] += 1  # Unknown types are ignored, as Kermit does.

    def _in_flight_in(self, packet: Packet) -> bool:
        """``packet`` may belong to the first flight of the request we
        answered (sent behind it, before our answer: no round trip), as
        far as we can tell: data numbered within its bound, before any
        beyond it arrived."""
        flight = self._flight_in
        return (
            flight is not None
            and not self._peer_data_seen
            and packet.type in (_T_DATA, _T_EOF)
            and packet.seq <= flight.packets
        )

    def _long_offer(self) -> int | None:
        """The long window this side may offer: None when it is turned off, or
        when the window was narrowed below 31 (1 is the paper's stop-and-wait:
        the window the user wants; long numbers only lift the ceiling)."""
        cfg = self.config
        return cfg.long_window if cfg.needs_long_window() else None

    def _on_repair(self, packet: Packet, now: float) -> None:
        """A repair packet (PROTOCOL.md 15.6): mend the damaged packet we
        hold that it is for and take it as if it had come whole; with none
        to mend (it was lost whole, or damaged beyond the sums), NAK it at
        once so that it comes again whole (or ACK it, received already)."""
        split = self._split_seq(packet)
        if split is None:
            return
        seq, field = split
        check = self._parser.check
        # The damaged packets of the repaired length, the one whose SEQ
        # character is the repair's first; at most REPAIR_TRIES of them (each
        # a try of the check: PROTOCOL.md 15.4).
        length = (field[0] - 32) << 6 | (field[1] - 32) if len(field) >= 2 else -1
        held = [i for i in range(len(self._damaged)) if len(self._damaged[i]) == length]
        held.sort(key=lambda i: (self._damaged[i][2] != packet.seq + 32, -i))
        for i in held[:REPAIR_TRIES]:
            fixed = apply_repair(self._damaged[i], field, check)
            if fixed is None or fixed[3] != _DATA_C or not 32 <= fixed[2] <= 95:
                continue
            head = EXTENDED_HEADER_LENGTH if fixed[1] == 32 else NORMAL_HEADER_LENGTH
            mended = Packet(
                seq=fixed[2] - 32, type=PacketType.DATA, data=fixed[head : len(fixed) - int(check)]
            )
            if (again := self._split_seq(mended)) is None or again[0] != seq:
                continue
            del self._damaged[i]
            self._counters["repairs_applied"] += 1
            self._on_packet(mended, now)
            return
        missing = self._receiver.missing(seq)
        if missing:
            self._counters["repairs_failed"] += 1
            self._queue_nak(seq)
        elif missing is not None:
            self._queue_ack(seq)  # (a repair's second copy, or a lost ACK's)

    def _split_seq(self, packet: Packet) -> tuple[int, bytes] | None:
        """``(sequence number on the wire, the rest of the data field)``.

        With long sequence numbers the data field of D, Z, N and data-Y
        packets starts with two characters that, before the SEQ character,
        spell the 18-bit number (PROTOCOL.md section 9).  A packet without
        them is counted as ignored (None): only a broken peer sends one, and
        its check was good, so it is not line damage to NAK.
        """
        if not self._long_seq:
            return packet.seq, packet.data
        n = decode18(packet.data[:2] + bytes((tochar(packet.seq),)))
        if n is None:
            self._counters["ignored_packets"] += 1
            return None
        return n, packet.data[2:]

    def _seq_fields(self, seq: int) -> tuple[int, bytes]:
        """``(SEQ, head of the data field)`` that carry sequence number ``seq``."""
        if not self._long_seq:
            return seq % 64, b""
        spelled = encode18(seq % LONG_SEQ_MODULUS)
        return unchar(spelled[2]), spelled[:2]

    def _on_ack(self, seq: int, data: bytes, now: float) -> None:
        cum: int | None
        window: int | None
        if self._long_seq:
            cum = decode18(data[:3]) if len(data) >= 3 else None
            window = decode18(data[3:6]) if len(data) >= 6 else None
            poll = data[6:7] == b"P"
        else:
            cum = unchar(data[0]) % 64 if len(data) >= 1 else None
            window = max(unchar(data[1]), 0) if len(data) >= 2 else None
            poll = data[2:3] == b"P"
        if window is not None:
            window = min(window, self._sender.window)
        fast = self._sender.fast_retransmit_count
        acked = self._sender.packets_acked
        self._sender.on_ack(seq, cum, window, now)
        if self._flight_floor and self._sender.base > self._flight_past:
            # The first packet sent after the answer is through: so is the
            # flight's queue, which its timers had to allow for.
            self._flight_floor = 0.0
        self._take_samples(now)
        if self._sender.packets_acked > acked:
            self._rtt.on_progress()
        self._counters["fast_retransmits"] += self._sender.fast_retransmit_count - fast
        if poll:
            self._queue_ack(self._receiver.last_in_order())
        self._check_closed(now)

    def _take_samples(self, now: float) -> None:
        """Feed the packets just acknowledged on their only copy to the
        round-trip and rate estimators (:mod:`serialsocket._rate`)."""
        delivered = self._sender.take_delivered()
        measured = False
        base = self._rate.base_rtt
        for pkt in delivered:
            rtt = now - pkt.done_at
            # The init's answer, the reference of fast_evidence, waited for
            # our early data too: a data packet's round trip is compared as
            # if it had, at the delivery rate the ACK clock measured (not a
            # hint: one too low made every sample look late, and the rate
            # was never corrected; 0.56 of the line instead of 0.98).
            line = self._rate.measured
            waited = self._early_chars / line if line else 0.0
            early = not self._rate.plausible(rtt, self._rtt.rttvar) or self._rate.fast_evidence(
                rtt + waited, self._tx(len(pkt.wire)), self._rtt.rttvar
            )
            if not early:
                # A packet that arrived sooner than the path allows left
                # sooner than the model said: its "round trip" is the
                # model's error, and would shrink the timeout below the path.
                self._rtt.sample(rtt)
                measured = True
            if pkt.mark is None:
                continue
            if self._pair is not None:
                self._pair_verdict(pkt, now)
            before = self._rate.rate
            if self._rate.on_delivery(
                pkt.mark, now, rtt, self._rtt.srtt, fast=early, wire_bytes=len(pkt.wire)
            ):
                self._rate_changed()
                if self._rate.busy_change and (before is None or (self._rate.rate or 0.0) < before):
                    self._rearm_queued(now, pkt.mark)
            if self._rate.pull_back > 0:
                self._pacer.pull_back(self._rate.pull_back, now)
            if self._rate.queue_delay > 0:
                free_at = self._rate.line_free_at(now, pkt.mark)
                if free_at is not None and self._pacer.catch_up(free_at):
                    self._rate.pushed()
        if self._rate.base_rtt != base:
            self._rate_changed()  # the timers' one-way delay follows the path
        if measured:
            self._measured()
        # A packet of the current length through on its only copy earns the
        # next step up (serialsocket/_length.py); a short tail packet does not.
        if self._adaptive:  # (_adapt_length does nothing otherwise: skip the any())
            full = 0.9 * (self._length.length + 1)
            self._adapt_length(clean=any(len(pkt.wire) >= full for pkt in delivered))

    def _pair_verdict(self, pkt: Outstanding, now: float) -> None:
        """``pkt``'s first copy was acknowledged at ``now``: if it is the second
        of the rate pair, the two ACKs' spacing tells the line's rate.

        Two packets handed over at the same instant leave the line back to
        back, however much waited ahead of them, so their ACKs come back the
        second's real transmit time apart: the line's rate, with no base round
        trip, model or init exchange in it.  The pacer cannot otherwise learn
        that a rate (a hint) is too low: it hands one packet per modelled
        transmit time into a line that is idle in between, the ACK clock then
        shows the handing rate, and with the UART's queue kept short
        (Pacer.tight) a packet leaves only (k - 1) real transmit times before
        the model said on a line k times faster -- less than fast_evidence's
        allowance for the init's own transmit times, for every k (a rate hint
        ten times low stayed in use for good: 0.098 of the line at 2400 bit/s
        and 20 s one way).  Without a rate, the first pair's measurement
        becomes it.  One pair a round trip until one shows the line no faster
        than the rate in use (_pair_due).
        """
        assert self._pair is not None
        lead, second = self._pair
        if pkt is lead:
            self._pair_lead_acked = now
            return
        if pkt is not second or pkt.mark is None:
            return
        acked = self._pair_lead_acked
        if acked is None:
            return  # the lead was lost or acknowledged with this one: no verdict
        first = self._rate.rate is None
        verdict = self._rate.on_pair(len(pkt.wire), now - acked, pkt.mark.sent_at, now)
        if verdict is None:
            return
        if verdict:
            self._rate_changed()
            if first:
                # The first window went out unpaced: what followed the pair
                # is still queued, and its timers ran from its handing under
                # the restart-on-progress rule that holds only without a rate
                # (31 packets at 128 characters are 16 s of a 2400 bit/s line
                # with no delay: one timed out half a second after the pair,
                # and its resend and a "loss" cut the packet length to 96).
                # Their timers only: their round trips still count from the
                # handing, so the queue shows and the pacer waits it out (a
                # pair 5 % low, moving their departures, made round trips
                # negative).
                self._rearm_queued(now, pkt.mark, departures=False)
        else:
            # The line is no faster: no more pairs, unless the rate drops far
            # (a timeout undid a raise to what the line delivered).
            self._pair_settled = self._rate.rate
            self._pacer.probe = False

    def _pair_due(self) -> bool:
        """A rate pair may go now: no pair has settled the rate in use (or
        it has dropped further below the one settled than a pair could show),
        the peer sent no data in the last round trip, and the last pair was
        answered (or resent: a resend's ACK is no sample)."""
        rate, settled = self._rate.rate, self._pair_settled
        if rate is not None and settled is not None and rate * PAIR_FASTER >= settled:
            return False
        # The peer's data spaces its ACKs by its line (on_pair tells nothing
        # then), and a pair is one more packet an expedited message may wait
        # behind: none while the way back carries data (a command session's
        # replies and telemetry).
        if self._clock - self._rate.reverse_at < (self._rtt.srtt or 0.0):
            return False
        if self._pair is None:
            return True
        lead, second = self._pair
        return second.acked or second.transmissions > 1 or lead.transmissions > 1

    def _rearm_queued(self, now: float, mark: RateMark, *, departures: bool = True) -> None:
        """The line is slower than the model that timed the packets in flight:
        move each one's departure, and its timer, to when it will really leave
        (with ``departures`` False, only its timer).

        The packet with ``mark`` left one base round trip before ``now``;
        every packet handed after it leaves when the bytes in between have
        drained at the measured rate.  Without this the first flight into an
        unknown or over-hinted line times out while still queued, and every
        resend joins the queue behind it (a retransmission storm).
        """
        left = self._rate.line_free_at(now, mark)
        rate = self._rate.rate
        if left is None or rate is None:
            return
        left -= (self._rate.handed - mark.handed_end) / rate  # when that packet left
        timeout = self._rtt.timeout()
        for pkt in self._sender.outstanding.values():
            if pkt.acked or pkt.deadline is None or pkt.mark is None or pkt.transmissions != 1:
                continue
            leaves = left + (pkt.mark.handed_end - mark.handed_end) / rate
            if leaves > pkt.done_at:
                if departures:
                    pkt.done_at = leaves
                if departures or pkt.deadline < leaves + timeout:
                    self._sender.arm(pkt, leaves + timeout)

    def _bits(self, chars_per_second: float | None) -> float | None:
        """Characters per second as the line's bits per second."""
        if chars_per_second is None:
            return None
        return chars_per_second * self.config.bits_per_char

    def _rate_hint(self) -> float | None:
        """The configured line rate in characters per second (None: not given)."""
        cfg = self.config
        return None if cfg.line_rate is None else cfg.line_rate / cfg.bits_per_char

    def _tx(self, wire_bytes: int) -> float:
        """Seconds the line needs for ``wire_bytes`` at the rate in use: the
        measured one once there is a measurement, the hint before (0 when
        neither is known)."""
        rate = self._rate.rate
        return 0.0 if rate is None else wire_bytes / rate

    def _rate_changed(self) -> None:
        """The rate in use or the path's base round trip moved: pacing, the
        timeout floor, the window bound and the receive buffer follow."""
        self._pacer.paced = self._rate.rate is not None
        if self._rate.measured is not None:
            self._flight_floor = 0.0  # (a measured rate times what is queued now)
        # The short UART queue only at the rate the user gave (see
        # Pacer.horizon), with a rate pair a round trip until one shows the
        # line no faster (_pair_verdict): an estimate still moving needs the
        # queue to see the line.
        self._pacer.tight = self._rate.rate is not None and self._rate.rate == self._rate_hint()
        self._pacer.probe = self._pair_due()
        if self._negotiated is not None:
            self._length_changed()
            self._adapt_length(clean=False)  # the cap in characters moves with the rate
            self._size_receive_buffer()
        self._window_key = None

    def _autotune(self, now: float) -> None:
        """Grow the receive buffer to what the application takes per round trip.

        A buffer sized from the hints starves a line that is faster or longer
        than they say (a rate hint 10x low kept the window a tenth of what
        Mars needs), and a receiver cannot measure the line through a window
        that holds the sender back.  So, as Linux's receive-buffer autotuning
        does: each round trip, the buffer becomes at least
        :data:`BUFFER_ROUND_TRIPS` times what the application read in the
        last one (judged from a quarter of it on, at the rate it is read):
        a sender held back by the window grows it every round trip, and a
        reader that does not keep up never grows it (the bytes counted are
        the ones read).  Never shrunk, capped by ``buffer_cap``.

        Bytes held behind a gap count as read: the reader would have taken
        them but for the loss, and a loss is exactly when the buffer must
        hold a round trip more.  (Counting only what was read, the buffer
        grew by what the window let through between gaps, and the window
        held a 300 s line to half its rate once a rate hint ten times low
        was corrected.)
        """
        srtt = self._rtt.srtt
        if srtt is None:
            return
        r = self._receiver
        taken = r.delivered_total - len(r.readable) + r.buffered_bytes
        span = now - self._tune_at
        if span > 0 and span >= srtt / TUNE_EARLY and self._tune_at > -math.inf:
            # From a quarter of a round trip on, at the rate it arrives: the
            # first full flight of a sender that just measured the line is
            # a round trip of line, and waiting for the round trip to end
            # held a 300 s line to a 64 KiB window for two more.
            want = int(BUFFER_ROUND_TRIPS * (taken - self._tune_taken) * max(srtt / span, 1.0))
            cap = self.config.buffer_cap
            if want > cap:
                self._buffer_capped = True
            r.receive_buffer = max(r.receive_buffer, min(want, cap))
        if span >= srtt:
            self._tune_at, self._tune_taken = now, taken

    def _on_data(self, seq: int, data: bytes, eof: bool, now: float) -> None:
        if self._last_data_at is not None:
            # The peer's data packets' spacing, the largest recent one
            # (decayed per packet like the peer's length): see _next_probe_time.
            gap = now - self._last_data_at
            before = self._data_gap
            self._data_gap = max(gap, self._data_gap * PEER_LENGTH_DECAY)
            if self._data_gap > before and DATA_GAP_SILENCE * self._data_gap > self._dead_after:
                self._dead_after = self._liveness()
                self._rtt.ceiling = self._ceiling()
        self._last_data_at = now
        # MARK, LEN, SEQ, TYPE, the long header's three and a CRC-16: the
        # peer's packet about as long as it was on the line.
        wire = max(len(data) + 10, int(self._peer_length * PEER_LENGTH_DECAY), LADDER[0])
        if wire != self._peer_length:
            self._peer_length = wire
            self._length_changed()
            self._fit_receive_window()
        self._autotune(now)
        arrival = self._receiver.on_packet(seq, data, eof, now, self._rtt.timeout())
        if self._receiver.discard and arrival.fields and self._state is State.ESTABLISHED:
            self._finish_abort("Connection closed: data refused", by_peer=False, send=True)
            return
        kind = arrival.classification
        if kind in ("old", "duplicate"):
            self._counters["duplicates_received"] += 1
        elif kind == "outside":
            self._counters["out_of_window"] += 1
        elif kind == "full":
            self._counters["dropped_buffer_full"] += 1
            # Not acknowledged (it did not fit), but answered: a window update
            # showing the shut window keeps the sender's liveness clock fresh,
            # or a slow reader would look like a dead link.
            self._queue_ack(self._receiver.last_in_order())
        self._receiver.take_fields(arrival, self._encoding)
        if arrival.ack is not None:
            if kind in ("old", "duplicate") and self._ack_on_its_way(arrival.ack, now):
                self._counters["duplicate_acks_held"] += 1
            else:
                self._queue_ack(arrival.ack)
                self._acked_at[arrival.ack] = now
                if len(self._acked_at) > ACKED_KEPT:
                    for old in list(self._acked_at)[: ACKED_KEPT // 2]:
                        del self._acked_at[old]
        if arrival.nak is not None:
            self._queue_nak(arrival.nak)
        if arrival.eof:
            self._events.append(EndOfStream())
        self._check_closed(now)

    def _on_urgent(self, packet: Packet) -> None:
        """An expedited fragment: ``tochar(more)`` then the encoded bytes."""
        more = unchar(packet.data[0]) if packet.data else -1
        if not 0 <= more < EXPEDITED_WINDOW:
            self._counters["ignored_packets"] += 1  # a broken peer's: its check was good
            return
        kind, completed = self._xrecv.on_fragment(packet.seq, more, packet.data[1:])
        for fields in completed:
            message = self._encoding.decode_fields(fields)  # MalformedDataError: abort
            if not self._receiver.discard:
                self._xrecv.inbox.append(message)
        if kind == "duplicate":
            self._counters["duplicates_received"] += 1
        elif kind == "outside":
            self._counters["out_of_window"] += 1
        if kind in ("new", "duplicate"):
            self._control.append(
                build_packet(
                    Packet(
                        seq=packet.seq,
                        type=URGENT_ACK,
                        data=bytes((tochar(self._xrecv.expected % 64),)),
                    ),
                    self._send_check,
                )
            )

    def _on_urgent_ack(self, packet: Packet, now: float) -> None:
        cumulative = unchar(packet.data[0]) % 64 if packet.data else None
        if self._xsend.on_ack(packet.seq, cumulative):
            self._counters["fast_retransmits"] += 1
        self._check_closed(now)

    def _on_latest(self, packet: Packet) -> None:
        """A latest value: ``tochar(number >> 6)`` then the encoded bytes."""
        high = unchar(packet.data[0]) if packet.data else -1
        if not 0 <= high < 64:
            self._counters["ignored_packets"] += 1  # a broken peer's: its check was good
            return
        number = high << 6 | packet.seq
        if self._lrecv.on_value(number, None):
            value = self._encoding.decode_fields([packet.data[1:]])  # MalformedDataError: abort
            if not self._receiver.discard:
                self._lrecv.deliver(value)
        else:
            self._counters["duplicates_received"] += 1
        self._control.append(
            build_packet(
                Packet(seq=packet.seq, type=LATEST_ACK, data=bytes((tochar(high),))),
                self._send_check,
            )
        )

    def _on_latest_ack(self, packet: Packet, now: float) -> None:
        high = unchar(packet.data[0]) if packet.data else -1
        if not 0 <= high < 64:
            self._counters["ignored_packets"] += 1
            return
        self._lsend.on_ack(high << 6 | packet.seq)
        self._check_closed(now)

    def _progress_mark(self) -> tuple[int, int]:
        """What a close's progress is measured by: our packets acknowledged
        (selectively too, EOF included) and the peer's packets received in order."""
        return self._sender.packets_acked, self._receiver.expected

    def _note_close_progress(self, now: float) -> None:
        """Re-arm the close deadline if this packet moved anything."""
        if self._close_deadline == math.inf or self._state is not State.ESTABLISHED:
            return
        mark = self._progress_mark()
        if mark != self._close_mark:
            self._close_mark = mark
            self._close_progress_at = now
            self._close_deadline = now + self._close_patience

    def _check_closed(self, now: float) -> None:
        both_closed = (
            self._sender.eof_acked and self._receiver.eof and self._xsend.idle and self._lsend.idle
        )
        if both_closed and allowed(self._state, Trigger.BOTH_CLOSED):
            self._go(Trigger.BOTH_CLOSED)
            # The ACK that completes the peer's close may be the last packet we
            # ever send: a program exits once its close is done, and the
            # linger below dies with it.  One lost ACK (1 % at a byte error
            # rate of 1e-3) left the netcat's sender "link dead" with every
            # byte delivered.  Extra copies cost a few characters.
            for _ in range(FINAL_ACK_COPIES):
                self._queue_ack(self._receiver.last_in_order())
            # The peer resends its EOF on its own, possibly backed-off, timer: stay
            # as long as it could keep trying before it would declare us dead.
            # A new connection request ends the linger early (see _on_init).
            self._linger_until = now + (self.config.linger or self._dead_after)
            self._events.append(ConnectionClosed())

    @staticmethod
    def _safe_text(data: bytes) -> str:
        try:
            raw = PRINTABLE.decode(data)
        except RemoteProtocolError:
            raw = data
        return raw.decode("utf-8", "replace")[:_ERROR_TEXT_MAX] or "peer aborted"

    # -- internals: packets out -----------------------------------------------------

    def _ack_on_its_way(self, seq_mod: int, now: float) -> bool:
        """Whether our last ACK of packet ``seq_mod`` left less than
        :data:`DUP_ACK_SLACK` round trips ago: a copy arriving now was sent
        before that ACK could have reached the peer (an idle copy, or a
        resend behind our queue), so another ACK would say nothing new and
        take the line from our data (PROTOCOL.md 4.2)."""
        at = self._acked_at.get(seq_mod)
        srtt = self._rtt.srtt
        return at is not None and srtt is not None and now - at < DUP_ACK_SLACK * srtt

    def _queue_ack(self, seq_mod: int, *, poll: bool = False) -> None:
        window = self._receiver.window_to_advertise()
        self._receiver.advertised = window
        if not self._long_seq and not poll and self._send_check is _CRC16 and window < 128:
            # The common case, once per data packet: a plain ACK under CRC-16
            # is one of 64 x 64 x 32 packets (SEQ, next expected, window).
            key = (seq_mod % 64) << 13 | (self._receiver.expected % 64) << 7 | window
            wire = _ACKS.get(key)
            if wire is None:
                data = bytes((tochar(self._receiver.expected % 64), tochar(window)))
                wire = _crc16_packet(seq_mod % 64, _ACK_C, data)
                if len(_ACKS) >= _ACKS_BOUND:
                    _ACKS.clear()
                _ACKS[key] = wire
            self._control.append(wire)
            return
        seq, head = self._seq_fields(seq_mod)
        if self._long_seq:
            expected = encode18(self._receiver.expected % LONG_SEQ_MODULUS)
            data = head + expected + encode18(window)
        else:
            data = bytes((tochar(self._receiver.expected % 64), tochar(window)))
        if poll:
            data += b"P"
        self._control.append(
            build_packet(Packet(seq=seq, type=PacketType.ACK, data=data), self._send_check)
        )

    def _queue_nak(self, seq_mod: int) -> None:
        self._counters["naks_sent"] += 1
        seq, head = self._seq_fields(seq_mod)
        self._control.append(
            build_packet(Packet(seq=seq, type=PacketType.NAK, data=head), self._send_check)
        )

    def _account(self, wire: bytes, now: float) -> float:
        """Count a packet handed to the line; returns when it finishes leaving the UART."""
        self._counters["packets_sent"] += 1
        self._counters["wire_bytes_sent"] += len(wire)
        self._rate.hand(len(wire))
        self._clock = max(self._clock, now)
        return self._pacer.send(len(wire), now)

    @property
    def _full_wire(self) -> int:
        """Wire bytes of a full data packet (the negotiated length once connected)."""
        return self._pacer.full_packet

    def _pacing_wake(self) -> float | None:
        s = self._sender
        self._pacer.probe = self._pair_due()
        wants = (
            s.has_retransmit()
            or (s.has_new_data() and s.room(self._effective_window()) > 0)
            or self._copy_due() is not None
        )
        wake = self._pacer.wake() if wants else None
        if self._lsend.may_send_new or self._lsend.resend_due:
            latest = self._pacer.idle_wake(LATEST_LEAD)
            if latest is not None:
                wake = latest if wake is None else min(wake, latest)
        return wake

    def _copy_due(self) -> Outstanding | None:
        """The packet an idle line should carry another copy of, if any
        (PROTOCOL.md 4.4): no resend waits, the rate is known (so the pacer
        knows the line is idle) and no queue is measured in front of it, the
        round trip is long against a packet, and nothing new can go -- none
        is queued (then the newest packets first), or the window is full
        (then the packet at its base)."""
        s = self._sender
        limit = self.config.idle_copies
        if (
            limit == 0
            or self._state is not State.ESTABLISHED
            or not s.in_flight()
            or s.has_retransmit()
            or self._rate.rate is None
            or self._rate.queue_delay > 0
            or not self._long_line()
            or self._clock - self._backlog_at > 2 * self._rtt_or_path()
        ):
            # The last condition: only a bulk sender's line is worth it --
            # one whose data waited for the line within two round trips.  A
            # command channel or a stream of teleoperation samples sends
            # as the line allows and never queues; copies there would only
            # make its next packet wait behind them.
            return None
        if not s.has_new_data():
            return s.peek_copy(limit)
        if s.room(self._effective_window()) <= 0:
            # A full window is a packet (or a run of them) at its base the
            # peer has not acknowledged: one that has cost a round trip
            # already, and holds everything behind it.
            return s.peek_base_copy(limit)
        return None

    def _rtt_or_path(self) -> float:
        return max(self._rtt.srtt or 0.0, self._min_rtt())

    def _long_line(self) -> bool:
        """The round trip is at least IDLE_COPY_MIN_PACKETS full packets:
        waiting for a repair costs many packet times of line."""
        tx = self._tx(self._full_wire)
        return tx > 0 and self._rtt_or_path() >= IDLE_COPY_MIN_PACKETS * tx

    def _preempt_due(self, queued_until: float, now: float) -> bool:
        """An expedited packet is due, and the line can drop the earlier
        bytes that would otherwise hold it more than PREEMPT_AFTER -- but
        not while a lane packet, or a packet sent again after the last drop,
        is still leaving: a stream of expedited messages would otherwise cut
        every data packet (and each other) and nothing would move.  So each
        drop is followed by the packets it cut, whole, and the stream
        advances between drops."""
        return (
            self.line_discards
            and queued_until - now > PREEMPT_AFTER
            and now >= self._uncut_until
            and self._xsend.has_due()
        )

    def _preempt(self, queued_until: float, now: float) -> None:
        """Cut in (PROTOCOL.md 11): the port drops what it holds unsent
        (:meth:`take_discard`) before this call's bytes go, so the expedited
        packet waits behind none of it.  Whatever the drop may have cut --
        every packet whose modelled departure was still to come -- goes
        again: data packets through the resend queue (not counted as losses:
        the packet length stays), lane fragments and the latest value at
        once (and :meth:`data_to_send` puts our ACK behind the expedited
        packet).  A packet the model
        wrongly thought cut reaches the peer twice and is dropped there as
        a duplicate; one it wrongly thought sent is repaired as a loss."""
        self._discard_due = True
        self._counters["preemptions"] += 1
        self._pacer.pull_back(queued_until - now, now)
        s = self._sender
        self._preempted = {seq for seq in self._preempted if seq in s.outstanding}
        cut = s.requeue_unsent(now)
        self._preempted.update(cut)
        self._counters["preempted_resends"] += len(cut)
        self._xsend.requeue_unsent(now)
        self._lsend.requeue_unsent(now)
        # Rate samples across the drop would count bytes that never left.
        self._rate.void(now)
        self._pair = None
        self._pair_lead_acked = None
        self._last_first = None

    def _release_expedited(self, now: float, out: list[bytes]) -> None:
        """Expedited fragments go out at once, ahead of paced data: they wait
        only behind what the UART already holds (the pacer keeps that under
        two packets), and the pacer counts them so data waits behind them."""
        timeout = self._rtt.timeout()
        while (frag := self._xsend.pop_due()) is not None:
            if not frag.wire:
                head = bytes((tochar(frag.more),))
                frag.wire = build_packet(
                    Packet(seq=frag.seq % 64, type=URGENT, data=head + frag.field),
                    self._send_check,
                )
            out.append(frag.wire)
            if frag.transmissions:
                self._counters["retransmissions"] += 1
            done_at = self._account(frag.wire, now)
            self._xsend.sent(frag, done_at, timeout, self._rtt.ceiling)
            # The lane never cuts its own packets (see _preempt_due).
            self._uncut_until = max(self._uncut_until, done_at)

    def _release_latest(self, now: float, out: list[bytes]) -> None:
        """The newest value, when the pacer has room after the stream's packets
        (at the last moment, so the freshest value goes); else its resend, if
        its timer ran out with nothing newer to send."""
        ls = self._lsend
        if not self._pacer.idle_within(now, LATEST_LEAD):
            return
        if ls.may_send_new:
            number, field = ls.take_new()
            wire = build_packet(
                Packet(
                    seq=number % 64, type=LATEST, data=bytes((tochar(number >> 6 & 63),)) + field
                ),
                self._send_check,
            )
        elif ls.resend_due:
            wire = ls.wire
            self._counters["retransmissions"] += 1
        else:
            return
        out.append(wire)
        ls.sent(wire, self._account(wire, now), self._rtt.timeout(), self._rtt.ceiling)

    def _release_data(self, now: float, out: list[bytes]) -> None:
        s = self._sender
        self._pacer.probe = self._pair_due()
        timeout = self._rtt.timeout()
        while s.has_retransmit() and self._pacer.has_room(now):
            pkt = s.pop_retransmit()
            assert pkt is not None
            preempted = pkt.seq in self._preempted
            if preempted:
                # Cut by an expedited packet's drop, not lost: the packet
                # length does not pay for it, and no drop cuts it again.
                self._preempted.discard(pkt.seq)
            else:
                self._length.lost()
                self._adapt_length(clean=False)
            repair = None if preempted else self._repair_for(pkt)
            if repair is not None:
                self._length.sent(len(repair))
                self._transmit(pkt, now, timeout, out, wire=repair)
                if not s.has_new_data():
                    # Nothing sent after it could show it lost before its
                    # timeout: a copy costs 15-30 characters of a line that
                    # would idle (as a whole resend at the end goes twice).
                    self._transmit(pkt, now, timeout, out, wire=repair)
                continue
            self._counters["retransmissions"] += 1  # (whole copies: repairs count apart)
            if not preempted:
                self._add_sums(pkt)
                self._length.sent(len(pkt.wire), corrected=pkt.wire[3] == _CORRECTED_C)
            self._transmit(pkt, now, timeout, out)
            if preempted:
                self._uncut_until = max(self._uncut_until, pkt.done_at)
            if (
                not preempted
                and (pkt.transmissions >= DOUBLE_FROM_COPY or not s.has_new_data())
                and self._long_line()
            ):
                # Lost on its resend too: it has held the window's base for
                # two round trips, and a third loss would add another.  Two
                # copies back to back make that one in 400 instead of one
                # in 20 (512 characters at 1e-4), for a packet of line time
                # in one of 400.  With nothing new to send (the end of a
                # transfer) every resend goes twice: the line would idle.
                self._counters["doubled_resends"] += 1
                self._transmit(pkt, now, timeout, out)
        if s.has_retransmit():
            return
        while self._pacer.has_room(now):
            room = s.room(self._effective_window())
            if not s.has_new_data() or room <= 0:
                if s.has_new_data():
                    self._backlog_at = now
                self._release_copies(now, timeout, out)
                return
            if s.queue:
                batch = self._pacer.batch(room, now)
                self._send_new(self._cut_capacity(), batch, now, timeout, out)
            else:
                self._send_eof_packet(now, timeout, out)
        if s.has_new_data():
            self._backlog_at = now  # the line, not the application, is the limit

    def _send_new(
        self,
        capacity: int,
        batch: int,
        now: float,
        timeout: float,
        out: list[bytes],
        *,
        keep: bool = False,
    ) -> bytes:
        """Cut up to ``batch`` new data packets of at most ``capacity`` data
        characters from the head of the send queue and send them; with
        ``keep`` (a first flight's, which may be put back), returns the
        bytes they took, else nothing."""
        s = self._sender
        sums = self._length.correcting
        short = not self._long_seq and self._send_check is _CRC16 and not sums
        # (A copy bounds the encoder's work: but for repeat counts, a
        # character carries a byte at most.)
        source = s.queue[: batch * capacity] if keep else s.queue
        taken = 0
        for field, used in self._encoding.encode_fields(source, capacity, batch):
            if short:
                # The encoder's field holds no MARK: no Packet to check it.
                wire = _crc16_packet(s.next % 64, _DATA_C, field)
            elif sums:
                seq, head = self._seq_fields(s.next)
                wire = build_corrected(seq, head + field, self._send_check)
                self._counters["corrected_sent"] += 1
            else:
                seq, head = self._seq_fields(s.next)
                wire = build_packet(
                    Packet(seq=seq, type=PacketType.DATA, data=head + field),
                    self._send_check,
                )
            if keep:
                taken += used
            else:
                del s.queue[:used]
            # Exposure counts first sends and resends, whose losses
            # show; an idle copy's or a doubled resend's would not.
            self._length.sent(len(wire), corrected=sums)
            self._mean_wire += (len(wire) - self._mean_wire) / 8
            self._transmit(s.add(wire, used, eof=False), now, timeout, out)
        if not keep:
            return b""
        took = bytes(s.queue[:taken])
        del s.queue[:taken]
        return took

    def _repair_for(self, pkt: Outstanding) -> bytes | None:
        """The repair packet to send in place of resending ``pkt`` whole, or
        None (PROTOCOL.md 15.6): only for the first resend of a ``D`` packet
        of at least :data:`REPAIR_MIN_LENGTH` characters, with sums agreed;
        with nothing new to send, only while :data:`REPAIR_END_HITS` allows."""
        wire = pkt.wire
        if (
            not self._correction
            or pkt.repair_sent
            or wire[3] != _DATA_C
            or not REPAIR_MIN_LENGTH <= len(wire) - 1 <= REPAIR_MAX_LENGTH
        ):
            return None
        q = self._length.byte_error_rate or 0.0
        if not self._sender.has_new_data() and q * len(wire) > REPAIR_END_HITS:
            return None
        pkt.repair_sent = True
        seq, head = self._seq_fields(pkt.seq)
        field = head + repair_field(wire[:-1], int(self._send_check))
        self._counters["repairs_sent"] += 1
        return build_packet(Packet(seq=seq, type=REPAIR_TYPE, data=field), self._send_check)

    def _add_sums(self, pkt: Outstanding) -> None:
        """A data packet lost before the sums went on is resent as a ``d``
        packet with the same data when sums pay at its length now and it
        still fits the peer's limit (PROTOCOL.md 15.5): at 1e-3 a
        513-character ``D`` arrives whole six times in ten, and one was lost
        five times running, each loss of its resend a timeout."""
        wire = pkt.wire
        agreed = self._negotiated
        if not self._correction or agreed is None or wire[3] != _DATA_C:
            return
        length = len(wire) - 1  # (MARK through CHECK: no CR)
        head = EXTENDED_HEADER_LENGTH if wire[1] == 32 else NORMAL_HEADER_LENGTH
        check = self._send_check
        sums = build_corrected(wire[2] - 32, wire[head : length - int(check)], check)
        if len(sums) - 1 <= agreed.send_max_length and self._length.sums_pay(length, len(sums) - 1):
            pkt.wire = sums
            self._counters["corrected_sent"] += 1

    def _send_eof_packet(self, now: float, timeout: float, out: list[bytes]) -> None:
        seq, head = self._seq_fields(self._sender.next)
        wire = build_packet(Packet(seq=seq, type=PacketType.EOF, data=head), self._send_check)
        self._transmit(self._sender.add(wire, 0, eof=True), now, timeout, out)

    def _release_flight(self, now: float, out: list[bytes]) -> None:
        """CONNECTING with a first flight announced: data packets numbered
        up to its bound go now, cut as the agreement we assumed says
        (PROTOCOL.md 14).  (An init that announces a flight carries no early
        data: the queue's head is the flight's.)"""
        s, flight = self._sender, self._flight
        assert flight is not None
        timeout = self._rtt.timeout()
        capacity = self._carried(flight.length)
        while s.next <= flight.packets and self._pacer.has_room(now):
            sent, written = s.next, len(out)
            if s.queue:
                self._flight_bytes += self._send_new(capacity, 1, now, timeout, out, keep=True)
            elif s.eof_requested and not s.eof_sent:
                self._send_eof_packet(now, timeout, out)
            else:
                break
            self._counters["flight_packets"] += s.next - sent
            self._flight_wire += sum(len(w) for w in out[written:])

    def _release_copies(self, now: float, timeout: float, out: list[bytes]) -> None:
        """Fill an idle line with copies of unacknowledged packets, newest
        first.  A copy is a retransmission on the wire; its timer runs from
        the copy, and its ACK gives no round-trip sample (Karn)."""
        self._release_latest(now, out)  # a fresh value before another copy
        while self._pacer.has_room(now) and (pkt := self._copy_due()) is not None:
            self._sender.take_copy(pkt, walk=not self._sender.has_new_data())
            self._counters["idle_copies"] += 1
            self._transmit(pkt, now, timeout, out)

    def _transmit(
        self,
        pkt: Outstanding,
        now: float,
        timeout: float,
        out: list[bytes],
        *,
        wire: bytes | None = None,
    ) -> None:
        """Hand a copy of ``pkt`` to the line (``wire``: a repair packet in
        its place) and arm its timer."""
        sent = pkt.wire if wire is None else wire
        out.append(sent)
        pkt.transmissions += 1
        self._sender.note_sent(pkt)
        pkt.done_at = self._account(sent, now)
        if pkt.transmissions == 1:
            pkt.mark = self._rate.mark(now)
            last = self._last_first
            if (
                last is not None
                and last[1] == now
                and pkt.done_at - now >= PAIR_QUEUED * self._tx(len(pkt.wire))
                and self._pair_due()
            ):
                # Behind another handed at the same instant: the rate pair.
                self._pair = (last[0], pkt)
                self._pair_lead_acked = None
                self._pacer.probe = False
            self._last_first = (pkt, now)
        else:
            self._last_first = None  # a resend between two breaks their pair
        self._sender.arm(pkt, pkt.done_at + timeout + self._queue_allowance())

    # -- internals: timing --------------------------------------------------------------

    def _connecting_timer(self, now: float) -> None:
        """CONNECTING: give up at the connect deadline, else resend the init when due."""
        if now >= self._connect_deadline:
            self._go(Trigger.CONNECT_TIMEOUT)
            self._events.append(
                ConnectionAborted(
                    reason="no answer to connect within "
                    f"{self.config.derived_connect_timeout():.1f} s",
                    by_peer=False,
                )
            )
        elif now >= self._init_deadline:
            self._rtt.on_timeout()
            self._counters["timeouts"] += 1
            self._send_init(now)

    def _established_timer(self, now: float) -> None:
        """ESTABLISHED: the silence verdict, the close deadline, retransmissions, probes."""
        silence = now - self._last_heard
        # Compare exactly as get_timer computes the deadline: rearranged, float
        # rounding can leave the timer due but never firing (a spin).
        if now >= self._last_heard + self._dead_after:
            self._declare_dead(silence)
            return
        if now >= self._close_deadline:
            # Checked after the silence verdict: a dead link is reported as dead.
            self._finish_abort(
                f"close made no progress for {self._close_patience:.1f} s", by_peer=False, send=True
            )
            return
        expired = self._sender.expired(now)
        # Without a rate, nothing models the queue in front of the line, and
        # a packet's own timer runs from when it was handed over: 31 packets
        # dumped on a 2400 bit/s line all timed out while the ones ahead of
        # them were being delivered, and every resend deepened the queue
        # (0.04 of the line, 15 000 timeouts, with no hints at 0 s delay).
        # So, as RFC 6298 5.3 restarts the timer when an ACK moves the
        # window, a packet whose timer ran out while the base kept moving is
        # re-armed a timeout after that progress (a loss stops the base; NAKs
        # and fast retransmit repair what lies beyond it).  With a rate the
        # pacer's model times each packet from its departure, and holding a
        # lost resend a further timeout costs a round trip: at 300 s one way
        # that was 0.80 of the limit instead of 0.91.
        hold = self._sender.base_advanced_at + self._rtt.timeout()
        if self._rate.rate is None and hold > now:
            for seq in expired:
                self._sender.arm(self._sender.outstanding[seq], hold)
            expired = []
        if expired:
            self._counters["timeouts"] += 1
            self._rtt.on_timeout()
            if self._rate.on_timeout():
                self._rate_changed()
                # The raise built a queue the model did not see: time the
                # packets still in it from when they will leave at the rate
                # now in use, as a busy run's lowering does, and resend only
                # those whose timer still runs out.  (Resent as well, they
                # joined that queue: 20 KB over a 300 bit/s line whose rate
                # had been taken for six times its own took 3145 s, not 1334.)
                last = self._rate.last_delivery
                if last is not None:
                    free_at = self._rate.line_free_at(*last)
                    if free_at is not None and self._pacer.catch_up(free_at):
                        self._rate.pushed()
                    self._rearm_queued(*last)
                    outstanding = self._sender.outstanding
                    expired = [q for q in expired if (outstanding[q].deadline or now) <= now]
            limit = self.config.max_retries
            for seq in expired:
                pkt = self._sender.outstanding[seq]
                if limit is not None and pkt.transmissions > limit:
                    self._finish_abort(
                        f"Too many retries (packet {seq % 64})", by_peer=False, send=True
                    )
                    return
                self._sender.schedule(seq)
        if self._xsend.expired(now):
            self._counters["timeouts"] += 1
            limit = self.config.max_retries
            worst = max(f.transmissions for f in self._xsend.outstanding.values())
            if limit is not None and worst > limit:
                self._finish_abort("Too many retries (expedited)", by_peer=False, send=True)
                return
        if self._lsend.expired(now) and self._lsend.pending is None:
            # Nothing newer to send instead: the last value goes again.
            self._counters["timeouts"] += 1
            limit = self.config.max_retries
            if limit is not None and self._lsend.transmissions > limit:
                self._finish_abort("Too many retries (latest value)", by_peer=False, send=True)
                return
        if now >= self._next_probe_time():
            self._last_probe = now
            self._queue_ack(self._receiver.last_in_order(), poll=True)

    def _liveness(self) -> float:
        """``dead_after`` as the endpoint applies it (see :class:`EndpointConfig`).

        The configured or derived value, raised while nothing is measured
        (derived only: an explicit value is the user's) to
        :data:`UNMEASURED_DEAD_AFTER`, and once the round trip is measured to
        :data:`OUTAGE_ROUND_TRIPS` of it plus two retransmission timeouts."""
        cfg = self.config
        base = self._derived_dead_after
        srtt = self._rtt.srtt
        if srtt is None:
            # A listener that heard the connector's init again and again after
            # answering knows the round trip is longer than that span, maybe
            # twice as long, and the connector doubles its wait: the next copy
            # comes a span later, three spans if one copy is damaged.  At 60 s
            # one way without hints the copies came 31 s apart, one was
            # damaged, and a 60 s verdict ended the link 60 s before the
            # connector's first data could arrive; at 300 s, with twice the
            # span, one damaged copy ended it 6 s before the next.
            unmeasured = max(UNMEASURED_DEAD_AFTER + 4 * self._answer_span, self._peer_patience)
            return base if cfg.dead_after is not None else max(base, unmeasured)
        # A receiver's own round trip (its EOF answered at once) says nothing
        # of how far apart the peer's packets come: one with nothing to send
        # judged the link dead 2.2 s into a 768-character packet at 2400 bit/s.
        measured = OUTAGE_ROUND_TRIPS * srtt + 2 * self._rtt.base_timeout()
        return max(base, measured, DATA_GAP_SILENCE * self._data_gap)

    @property
    def _peer_patience(self) -> float:
        """What the connector's init says the silence after our answer may
        last (see PEER_TIMEOUT_SILENCE): 300 s one way with hints left a
        listener without them judging the link dead 60 s after answering, a
        round trip before the connector's first data could arrive."""
        factor = PEER_TIMEOUT_SILENCE * (2 if self._peer_timeout >= TIMEOUT_HINT_MAX else 1)
        return factor * self._peer_timeout

    def _ceiling(self) -> float:
        """The most retransmission backoff may reach: a minute (or 8 initial
        timeouts, or two measured timeouts, on slower paths), and at most half
        of ``dead_after``: then within any ``dead_after`` of silence a copy
        leaves with half of it to spare for its answer, so the verdict needs a
        copy that had ample time and still went unanswered, not merely a timer
        that outgrew the liveness clock."""
        # (_rtt.initial is the configuration's initial_timeout(), computed once.)
        slow = max(60.0, 8 * self._rtt.initial, 2 * self._rtt.base_timeout())
        return min(slow, self._dead_after / 2)

    def _measured(self) -> None:
        """A round trip was measured: liveness, backoff and the receive buffer
        follow the path, not the hints."""
        self._dead_after = self._liveness()
        self._rtt.ceiling = self._ceiling()
        if self._negotiated is not None:
            self._size_receive_buffer()
        if self._close_deadline != math.inf and self._close_patience_given is None:
            # A close's default patience is dead_after as measured now (see
            # close): 31 packets queued in a pty at 2400 bit/s drain for 16 s,
            # and a close that kept the 2.6 s of its first answer gave up on a
            # transfer that was moving.
            self._close_patience = self._dead_after
            self._close_deadline = self._close_progress_at + self._close_patience

    def _size_receive_buffer(self) -> None:
        """Grow the receive buffer to :data:`BUFFER_ROUND_TRIPS` of the line's
        bandwidth-delay product (at least ``receive_buffer``, at most
        ``buffer_cap``; never shrunk, so no advertised window is taken back).

        The sender keeps up to three round trips of packets unacknowledged to
        ride out the repair of a loss (PROTOCOL.md 4.6), and everything after
        a lost packet waits here until the repair arrives: a buffer smaller
        than that closes the window on a long fast line (Mars: 2400 bit/s
        and a 40-minute round trip is 576 kB a round trip).
        """
        cfg = self.config
        want = cfg.receive_buffer
        rate = self._rate.rate
        if rate is not None:
            rtt = max(self._rtt.srtt or 0.0, 2 * self._one_way())
            product = BUFFER_ROUND_TRIPS * rate * rtt
            need = int(product) if math.isfinite(product) else cfg.buffer_cap + 1
            self._buffer_capped = need > cfg.buffer_cap
            want = max(want, min(need, cfg.buffer_cap))
        self._receiver.receive_buffer = max(self._receiver.receive_buffer, want)

    def _fit_receive_window(self) -> None:
        """Count the advertised window in packets as long as the peer's recent
        longest, not as long as our receive limit: with 1024 announced and
        128-character packets arriving, a 64 KiB buffer offered 64 packets,
        and a 20 s line without hints ran at half speed.  Recent: the peer's
        first round trip of 512-character packets, cut to 96 after, held a
        20 s line to a fifth of its window (0.55 of the limit where fixed
        lengths made 0.97).  Not twice it, though a measuring peer may double
        its length in a step: at 300 s without hints that halved the window
        while the buffer was still the default.  A packet the buffer cannot
        take is dropped, counted, and resent."""
        agreed = self._negotiated
        if agreed is not None:
            longest = min(self._peer_length, agreed.receive_max_length)
            self._receiver.capacity = data_capacity(longest, agreed.check)

    def _length_changed(self) -> None:
        """The data packet length moved: the pacer's full packet and the
        timeout floor follow."""
        self._pacer.full_packet = self._length.length + 1
        self._rtt.floor = self._timeout_floor(self._length.length, self._peer_length)

    def _adapt_length(self, *, clean: bool) -> None:
        """Cut new data packets to the length the measured error rate favours
        (:mod:`serialsocket._length`; ``clean``: a packet of the current length
        was just acknowledged on its only copy), within the peer's limit and
        ``max_packet_time`` at the rate in use.  Below the starting length only
        with long sequence numbers: 31 shorter packets might not cover the
        line's round trip."""
        agreed = self._negotiated
        if agreed is None:
            return
        corrected = self._carried_corrected if self._correction else None
        if not self._adaptive:
            # A fixed length: only whether sums pay at it is chosen.
            fixed = self._length.length
            self._length.choose(fixed, fixed, self._carried, clean=clean, corrected=corrected)
            return
        upper = self.config.measured_length_cap(agreed.send_max_length, self._rate.rate)
        lower = LADDER[0] if self._long_seq else self._start_length
        before = self._length.length
        if (
            self._length.choose(lower, upper, self._carried, clean=clean, corrected=corrected)
            != before
        ):
            self._length_changed()

    def _carried(self, length: int) -> int:
        """Data characters a data packet of ``length`` carries."""
        capacity = data_capacity(length, self._send_check)
        return capacity - 2 if self._long_seq else capacity

    def _carried_corrected(self, length: int) -> int:
        """Data characters a ``d`` packet of ``length`` carries (its sums
        take three characters per block, PROTOCOL.md 15)."""
        return self._carried(length) - trailer_length(length, int(self._send_check))

    def _cut_capacity(self) -> int:
        """Data characters of the next new data packet, sums or not."""
        if self._length.correcting:
            return self._carried_corrected(self._length.length)
        return self._carried(self._length.length)

    def _timeout_floor(self, send_max_length: int, receive_max_length: int) -> float:
        """Physical round trip of our full packet, plus the peer's pacing queue
        (two of its packets, which are at most our receive limit), plus 10 %."""
        rtt = self._physical_rtt(send_max_length + 1)
        return 1.1 * (rtt + 2 * self._tx(receive_max_length + 1)) + 0.005

    def _one_way(self) -> float:
        """The one-way delay the timers assume: the hint, until the path's
        base round trip is measured; then the measurement where it is
        shorter (a hint 10x too long made every timeout floor and the NAK
        horizon ten round trips long) or where there was no hint.  A
        measurement never lengthens a given hint: it includes a reader's
        batching, and the hint's exact timing is what a NAK is judged by."""
        hint = self.config.one_way_delay
        base = self._rate.base_rtt
        if base is None:
            return hint
        measured = max((base - self._tx(_ACK_WIRE)) / 2, 0.0)
        return measured if hint == 0 else min(hint, measured)

    def _physical_rtt(self, packet_bytes: int) -> float:
        """:meth:`EndpointConfig.physical_rtt` at the rate in use."""
        return 2 * self._one_way() + self._tx(packet_bytes + _ACK_WIRE)

    def _min_rtt(self) -> float:
        return self._physical_rtt(self._full_wire)

    def _nak_horizon(self) -> float:
        """The least time from a copy leaving our UART to a NAK *about that copy*.

        The copy's last byte reaches the peer one delay after it left our
        UART (``done_at`` already includes its own transmit time); the peer can
        reject it only then, and its NAK -- the shortest packet there is, with
        the negotiated check -- needs its own transmit time and one more delay.
        A NAK arriving sooner was provoked by an earlier copy and must not
        cause another resend; one arriving later may be about this copy and is
        honoured.  (The physical round trip of a full packet is too long by the
        packet's own transmit time: it made every NAK for a damaged packet
        arrive just too early, and stop-and-wait waited for the timeout.)

        Neither end waits for a CR: the peer rejects the copy at its last
        check character, one character before the CR that ``done_at``
        includes, and our parser completes the NAK at its own last check
        character.  Counting both CRs set the horizon two character times
        late, and on a line without jitter every NAK about a damaged packet
        was ignored (a timeout repaired it instead; found by the Wireshark
        dissector).  The NAK carries the two-character head of long sequence
        numbers when they are in use.
        """
        head = b"  " if self._long_seq else b""
        nak = len(build_packet(Packet(seq=0, type=PacketType.NAK, data=head), self._send_check))
        cr = self._tx(1)
        # The delay is an estimate (a measured base round trip includes the
        # peer's ACK decision): a NAK about this very copy arrived 0.08 s
        # inside an exact horizon at 1.3 s one way and was ignored, and the
        # timeout that repaired the copy instead came 6 s later.  A NAK about
        # an earlier copy comes before this copy was handed over, or one of
        # the peer's repeats, at most one per its retransmission timeout.
        delays = 2 * self._one_way() * (1.0 - NAK_HORIZON_SLACK)
        return delays + self._tx(nak) - 2 * cr - TIME_EPSILON

    def _effective_window(self) -> int:
        # (Without a rate the first flight grows with every ACK: see below.)
        acked = self._sender.packets_acked if self._rate.rate is None else -1
        key = (self._sender.window, self._rtt.srtt, self._window_wire(), self._rate.measured, acked)
        if key != self._window_key:
            self._window_key = key
            self._window_cached = self._compute_effective_window()
        return self._window_cached

    def _window_wire(self) -> int:
        """Wire bytes of the packets the window is counted in: full ones, or the
        recent data packets' mean when shorter, rounded up to 16.  A window
        counted in 1024-character packets held telemetry of 176 characters a
        packet to 31 packets a round trip, and it queued behind them."""
        mean = min(self._full_wire, math.ceil(self._mean_wire / 16) * 16)
        return max(mean, 16)

    def _compute_effective_window(self) -> int:
        window = self._sender.window
        wire = self._window_wire()
        tx = self._tx(wire)
        if tx <= 0:
            # Rate unknown: nothing says how much the line holds.  With mod-64
            # numbers, the classic 31 packets.  With long sequence numbers,
            # slow start from there: twice what the line was measured to
            # deliver in a round trip, so the window doubles each round trip
            # until a queue forms and the busy run measures the rate (31
            # packets never fill a 20-minute line, so without this the rate
            # was never measured and 300 s one way ran at 0.02 of the line).
            # The first flight, before a rate is known, waits in the queue
            # in front of the line, cut to lengths chosen before any
            # evidence, until the rate pair (its first two packets) sets the
            # rate about one init round trip later.  31 packets of 128
            # characters are 16 s of a 2400 bit/s line: at no delay, 0.89 of
            # the line at best where 0.93 was wanted.  So only what a 9600
            # bit/s line would carry in that round trip goes (a slower line
            # still has a queue until the verdict; a faster one on a short
            # path idles for that round trip), and one more packet with each
            # acknowledged, as TCP's slow start grows: pairs give no verdict
            # while the peer's data comes back, and a window held to the
            # first flight would never build the queue a busy run measures.
            first = MAX_WINDOW
            if (init := self._rate.init_rtt) is not None:
                flight = math.ceil(init * FIRST_FLIGHT_RATE / wire) + self._sender.packets_acked
                first = max(FIRST_FLIGHT_MIN, min(MAX_WINDOW, flight))
            measured, srtt = self._rate.measured, self._rtt.srtt
            if not self._long_seq or measured is None or srtt is None:
                return min(window, first)
            grown = math.ceil(2 * measured * srtt / wire) + 5
            return max(1, min(window, max(first, grown)))
        rtt = max(self._rtt.srtt if self._rtt.srtt is not None else 0.0, self._min_rtt())
        # The window must outlast the repair of a loss, or the line idles.
        # Packet k (first sent from T - tx to T) is lost; the next packet's
        # ACK and NAK reach us at T + tx + 2 x delay + tx(ACK); the resend
        # waits behind at most two paced packets and leaves at T + 2 x delay +
        # 4 tx + tx(ACK); its ACK returns 2 x delay + tx(ACK) later.  The
        # window k..k+W-1 (plus the resend's own slot) keeps the line busy
        # until T + W tx, so W tx >= 2 rtt + 2 tx.  If the resend is lost too,
        # the next new packet's ACK reveals it (fast retransmit) one round
        # trip and two packets later: 3 rtt + 4 tx.  One packet more absorbs
        # reading in batches and rounding.  Pacing keeps the UART queue at
        # two packets, so these packets are on the line, not in a tty buffer.
        #
        # With long sequence numbers the window may reach further: a packet
        # lost twice (1 in 20 losses with 512-character packets at 1e-4)
        # holds the window's base for three round trips, and at Mars distance
        # each round trip the line idles is 40 minutes.  LONG_REPAIR_ROUND_TRIPS
        # covers a resend lost twice; the receive buffer grows to match.
        trips = LONG_REPAIR_ROUND_TRIPS if self._long_seq else 3
        bdp = math.ceil(trips * rtt / tx) + 5
        return max(1, min(window, bdp))

    def _next_probe_time(self) -> float:
        """Probe when the peer has been quiet for a quarter of ``dead_after``,
        and for twice the recent gap between its data packets: a receiver
        whose own round trip is short (its EOF answered at once) polled
        between every two of a netcat's 512-character packets at 2400 bit/s,
        and each answer took 15 characters of the busy line (3 % of it)."""
        interval = max(self._dead_after / 4, 2 * self._data_gap)
        if self._sender.in_flight():
            return math.inf  # Retransmissions already probe.
        return max(self._last_heard, self._last_probe) + interval
