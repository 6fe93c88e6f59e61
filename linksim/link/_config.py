"""Link impairment parameters: frozen dataclasses, TOML loading and named presets.

A :class:`LinkConfig` describes a full-duplex line between end ``a`` and end
``b``: one :class:`DirectionConfig` per direction plus the seed from which each
direction derives its own random streams.  Every parameter is optional; the
default :class:`DirectionConfig` is a perfect, instantaneous line.

Times are seconds on the link's own clock, which starts at 0 when the link
(the in-memory channel or the pty relay) starts.  Rates are probabilities per
*byte* (the unit of damage on a UART), not per bit.

Invalid values raise :class:`ConfigError` (a :class:`ValueError`) naming the
field and the allowed range.  This module is sans-I/O apart from
:meth:`LinkConfig.from_toml`, which may read the file it is given.
"""

from __future__ import annotations

import enum
import math
import pathlib
import tomllib
from collections.abc import Mapping
from dataclasses import dataclass, field, fields, replace
from typing import Any

from linksim._errors import ConfigError

__all__ = [
    "PRESETS",
    "ConfigError",
    "DirectionConfig",
    "FaultAction",
    "GilbertElliott",
    "LinkConfig",
    "Outage",
    "ScriptedFault",
]


def _is_number(value: object) -> bool:
    """An int or float, but not a bool (TOML ``true`` must not read as 1)."""
    return isinstance(value, int | float) and not isinstance(value, bool)


def _check_probability(name: str, value: float) -> None:
    if not (_is_number(value) and 0.0 <= value <= 1.0):
        raise ConfigError(f"{name} must be a probability in [0, 1], got {value!r}")


def _check_nonnegative(name: str, value: float) -> None:
    if not (_is_number(value) and math.isfinite(value) and value >= 0.0):
        raise ConfigError(f"{name} must be a finite number >= 0, got {value!r}")


@dataclass(frozen=True, slots=True)
class GilbertElliott:
    """Gilbert-Elliott burst errors: a two-state Markov chain stepped once per character time.

    In the *good* state each byte is hit with probability ``error_good``, in the
    *bad* state with ``error_bad``.  Every character time of the line (10 bits
    at its rate), sent on or idle, the chain leaves the good state with
    probability ``p_good_to_bad`` and the bad state with ``p_bad_to_good``, so a
    bad burst lasts on average ``1 / p_bad_to_good`` character times
    (geometrically distributed) -- the same span of time whether the direction
    carries bulk data or one ACK a second -- and the long-run fraction of bad
    time is ``p_good_to_bad / (p_good_to_bad + p_bad_to_good)``.  Under
    back-to-back traffic that is exactly a chain stepped once per byte.  On a
    line without a rate there is no character time: the chain steps once per
    byte sent.  A hit corrupts the byte (random bit flips) or, with
    ``drop=True``, removes it.
    """

    p_good_to_bad: float
    p_bad_to_good: float
    error_good: float = 0.0
    error_bad: float = 0.5
    drop: bool = False

    @classmethod
    def parse(cls, text: str) -> GilbertElliott:
        """``P_GB:P_BG[:ERROR_BAD[:ERROR_GOOD]]`` (``--burst``, or ``burst = "..."`` in TOML)."""
        try:
            values = [float(x) for x in text.split(":")]
            if not 2 <= len(values) <= 4:
                raise ValueError
        except ValueError:
            raise ConfigError(
                f"burst wants P_GB:P_BG[:ERROR_BAD[:ERROR_GOOD]], got {text!r}"
            ) from None
        values += [0.5, 0.0][len(values) - 2 :]  # defaults: error_bad 0.5, error_good 0
        return cls(
            p_good_to_bad=values[0],
            p_bad_to_good=values[1],
            error_bad=values[2],
            error_good=values[3],
        )

    def spec(self) -> str:
        """The ``P_GB:P_BG:ERROR_BAD:ERROR_GOOD`` text :meth:`parse` reads (not ``drop``)."""
        return (
            f"{self.p_good_to_bad!r}:{self.p_bad_to_good!r}:{self.error_bad!r}:{self.error_good!r}"
        )

    def __post_init__(self) -> None:
        for name in ("error_good", "error_bad"):
            _check_probability(f"burst.{name}", getattr(self, name))
        for name in ("p_good_to_bad", "p_bad_to_good"):
            value = getattr(self, name)
            if not (_is_number(value) and 0.0 < value <= 1.0):
                raise ConfigError(f"burst.{name} must be in (0, 1], got {value!r}")


@dataclass(frozen=True, slots=True)
class Outage:
    """Loss of signal during ``[start, end)`` seconds of link time.

    A byte is lost if it is *on the wire* at any moment of the outage: from the
    start of its serialisation at the UART to its arrival at the far end (the
    closed interval ``[departure - char_time, arrival]``).
    """

    start: float
    end: float

    @classmethod
    def parse(cls, text: str) -> Outage:
        """``T1:T2`` in seconds (``--outage``, or an ``outage`` list entry in TOML)."""
        try:
            start, end = (float(x) for x in text.split(":"))
        except ValueError:
            raise ConfigError(f"an outage is T1:T2 in seconds, got {text!r}") from None
        return cls(start, end)

    def __post_init__(self) -> None:
        _check_nonnegative("outage.start", self.start)
        _check_nonnegative("outage.end", self.end)
        if self.end <= self.start:
            raise ConfigError(f"outage.end must be > outage.start, got {self.start}:{self.end}")


class FaultAction(enum.Enum):
    """What a :class:`ScriptedFault` does to its target."""

    DROP = "drop"
    CORRUPT = "corrupt"
    INSERT = "insert"


@dataclass(frozen=True, slots=True)
class ScriptedFault:
    """One reproducible fault, addressed by position in the byte stream.

    Exactly one target:

    * ``byte=N``: the byte at 0-based position ``N`` of everything written to
      this direction ("corrupt byte 1000");
    * ``packet=N``: the ``N``-th (1-based) packet, where a packet starts at each
      occurrence of ``starts_with`` and runs through the first ``end`` byte or
      up to the next occurrence ("drop the 3rd packet that starts with SOH").
      Bytes of ``starts_with`` equal to ``wildcard`` match any byte, so
      ``starts_with=b"\\x01??Y", wildcard=ord("?")`` selects Kermit ACKs.

    ``DROP`` removes the byte or the whole packet; ``CORRUPT`` XORs the target
    byte (for a packet, the byte at ``offset`` within it) with ``xor``;
    ``INSERT`` puts ``data`` on the line just before the target.

    A write that ends in a proper prefix of a multi-byte ``starts_with`` holds
    those bytes back until the next write settles whether they start a packet.
    """

    action: FaultAction
    byte: int | None = None
    packet: int | None = None
    starts_with: bytes = b"\x01"
    wildcard: int | None = None
    end: int | None = 0x0D
    offset: int = 0
    xor: int = 0xFF
    data: bytes = b""

    def __post_init__(self) -> None:
        if not isinstance(self.action, FaultAction):
            raise ConfigError(f"fault.action must be one of drop/corrupt/insert: {self.action!r}")
        if (self.byte is None) == (self.packet is None):
            raise ConfigError("fault needs exactly one target: byte=N (>= 0) or packet=N (>= 1)")
        if self.byte is not None and self.byte < 0:
            raise ConfigError(f"fault.byte must be >= 0, got {self.byte}")
        if self.packet is not None and self.packet < 1:
            raise ConfigError(f"fault.packet must be >= 1, got {self.packet}")
        if not self.starts_with or self.starts_with[0] == self.wildcard:
            raise ConfigError("fault.starts_with must be non-empty and begin with a literal byte")
        if not 1 <= self.xor <= 255:
            raise ConfigError(f"fault.xor must be in [1, 255], got {self.xor}")
        if self.offset < 0:
            raise ConfigError(f"fault.offset must be >= 0, got {self.offset}")
        if self.action is FaultAction.INSERT and not self.data:
            raise ConfigError("fault.data must be non-empty for an insert fault")


@dataclass(frozen=True, slots=True)
class DirectionConfig:
    """Impairments of one direction of the line; all optional and combinable.

    * ``rate``: line rate in bit/s (``None``: infinitely fast).  Each character
      occupies the UART for ``bits_per_char / rate`` seconds (8N1 = 10 bits).
    * ``delay``: fixed one-way propagation delay in seconds.
    * ``jitter``: extra delay drawn uniformly from ``[0, jitter]`` per byte;
      arrival times never decrease, so jitter never reorders.
    * ``loss``: probability that a byte vanishes.
    * ``byte_error_rate``: probability that a byte is corrupted (XOR with a
      random non-zero mask, i.e. random bits flipped).
    * ``noise``: probability, per byte, that a random noise byte follows it.
    * ``burst``: Gilbert-Elliott burst errors, see :class:`GilbertElliott`.
    * ``outages``: scheduled losses of signal.
    * ``faults``: scripted faults, see :class:`ScriptedFault`.
    """

    rate: float | None = None
    bits_per_char: int = 10
    delay: float = 0.0
    jitter: float = 0.0
    loss: float = 0.0
    byte_error_rate: float = 0.0
    noise: float = 0.0
    burst: GilbertElliott | None = None
    outages: tuple[Outage, ...] = ()
    faults: tuple[ScriptedFault, ...] = ()

    def __post_init__(self) -> None:
        if self.rate is not None and not (
            _is_number(self.rate) and math.isfinite(self.rate) and self.rate > 0
        ):
            raise ConfigError(
                f"rate must be a finite number of bit/s > 0 or None, got {self.rate!r}"
            )
        if not (
            _is_number(self.bits_per_char)
            and isinstance(self.bits_per_char, int)
            and 1 <= self.bits_per_char <= 64
        ):
            raise ConfigError(
                f"bits_per_char must be an integer in [1, 64], got {self.bits_per_char!r}"
            )
        _check_nonnegative("delay", self.delay)
        _check_nonnegative("jitter", self.jitter)
        for name in ("loss", "byte_error_rate", "noise"):
            _check_probability(name, getattr(self, name))

    @property
    def char_time(self) -> float:
        """Seconds one character occupies the UART (0 on an infinitely fast line)."""
        return 0.0 if self.rate is None else self.bits_per_char / self.rate

    @property
    def is_lossless(self) -> bool:
        """True when every byte written arrives unchanged (only timing is impaired)."""
        return (
            self.loss == 0
            and self.byte_error_rate == 0
            and self.noise == 0
            and self.burst is None
            and not self.outages
            and not self.faults
        )


# Named presets (the list).  noisy-moon's bursts: a fade starts on
# average every 20 000 bytes (~83 s at 2400 bit/s), lasts 1/0.05 = 20 bytes on
# average, and hits 30 % of the bytes inside it -- long enough to destroy a
# whole 128-byte packet now and then, rare enough that the ARQ keeps up.
_PRESET_DIRECTIONS: dict[str, DirectionConfig] = {
    "clean": DirectionConfig(),
    "phone-2400": DirectionConfig(rate=2400, delay=0.05, byte_error_rate=1e-5),
    "moon": DirectionConfig(rate=9600, delay=1.3),
    "noisy-moon": DirectionConfig(
        rate=2400,
        delay=1.3,
        byte_error_rate=1e-4,
        burst=GilbertElliott(p_good_to_bad=5e-5, p_bad_to_good=0.05, error_bad=0.3),
    ),
    "geo": DirectionConfig(delay=0.27),
    # Mars near conjunction: 20 light-minutes each way, a 2400 bit/s link,
    # byte errors (issue 20).  A round trip is 40 minutes; only long sequence
    # numbers keep such a line busy (serialsocket/PROTOCOL.md section 9).
    "mars": DirectionConfig(rate=2400, delay=1200.0, byte_error_rate=1e-4),
}
PRESETS: tuple[str, ...] = tuple(_PRESET_DIRECTIONS)


@dataclass(frozen=True, slots=True)
class LinkConfig:
    """A full-duplex line: ``a_to_b`` and ``b_to_a`` impairments and a seed.

    Each direction draws from its own random streams derived from
    ``(seed, direction)``, so the same seed and the same writes give the same
    impairments byte for byte.
    """

    a_to_b: DirectionConfig = field(default_factory=DirectionConfig)
    b_to_a: DirectionConfig = field(default_factory=DirectionConfig)
    seed: int = 0

    def __post_init__(self) -> None:
        if not (isinstance(self.seed, int) and _is_number(self.seed)) or self.seed < 0:
            raise ConfigError(f"seed must be an integer >= 0, got {self.seed!r}")

    @classmethod
    def symmetric(cls, direction: DirectionConfig, *, seed: int = 0) -> LinkConfig:
        """The same impairments both ways."""
        return cls(a_to_b=direction, b_to_a=direction, seed=seed)

    @classmethod
    def preset(cls, name: str, *, seed: int = 0) -> LinkConfig:
        """A named preset: one of :data:`PRESETS` (symmetric)."""
        try:
            direction = _PRESET_DIRECTIONS[name]
        except KeyError:
            raise ConfigError(f"preset must be one of {', '.join(PRESETS)}; got {name!r}") from None
        return cls.symmetric(direction, seed=seed)

    @classmethod
    def from_toml(cls, source: str | pathlib.Path) -> LinkConfig:
        """Load a config from a TOML file (a :class:`~pathlib.Path`) or TOML text (a str).

        Layout: optional top-level ``preset`` (the base) and ``seed``; a
        ``[both]`` table applied to both directions, then ``[a_to_b]`` and
        ``[b_to_a]`` overriding it.  Direction keys are the command-line flag
        names (``rate``, ``bits``, ``delay``, ``jitter``, ``loss``, ``ber``,
        ``noise``, ``burst``, ``outage``) or the :class:`DirectionConfig`
        field names, one name per setting; ``burst`` is ``"P_GB:P_BG[:E_BAD[:E_GOOD]]"``
        as on the command line or a table of :class:`GilbertElliott` fields;
        ``outage`` a list of ``"T1:T2"`` or ``[start, end]``;
        ``faults`` an array of tables of :class:`ScriptedFault` fields with
        ``action = "drop" | "corrupt" | "insert"`` and byte strings given as
        text (each character one byte, ``"\\u0001"`` for SOH).
        """
        if isinstance(source, pathlib.Path):
            try:
                text = source.read_text(encoding="utf-8")
            except (OSError, UnicodeDecodeError) as exc:
                raise ConfigError(f"cannot read {source}: {exc}") from exc
        else:
            text = source
        try:
            doc = tomllib.loads(text)
        except tomllib.TOMLDecodeError as exc:
            raise ConfigError(f"invalid TOML: {exc}") from exc
        return cls.from_mapping(doc)

    def to_toml(self) -> str:
        """This config as a commented TOML file :meth:`from_toml` reads back equal.

        Keys are the command-line flag names (``ber``, ``bits``, ``outage``...);
        unset options appear commented out, with their units, so the file is
        also a template (``linksim relay --write-config FILE``)."""
        lines = [
            "# telelink line configuration: linksim ... --config FILE",
            "# Keys are the command-line flag names; times in seconds, rates in bit/s,",
            "# loss / ber / noise are probabilities per byte.  A top-level",
            '# preset = "noisy-moon" would start from a preset instead of a clean line.',
            f"seed = {self.seed}",
        ]
        if self.a_to_b == self.b_to_a:
            lines += ["", "[both]  # each direction the same; [a_to_b] / [b_to_a] override"]
            lines += _direction_toml(self.a_to_b)
        else:
            for name, direction in (("a_to_b", self.a_to_b), ("b_to_a", self.b_to_a)):
                lines += ["", f"[{name}]"]
                lines += _direction_toml(direction)
        return "\n".join(lines) + "\n"

    @classmethod
    def from_mapping(cls, doc: Mapping[str, Any]) -> LinkConfig:
        """Build a config from a parsed TOML document (see :meth:`from_toml`)."""
        unknown = set(doc) - {"preset", "seed", "both", "a_to_b", "b_to_a"}
        if unknown:
            raise ConfigError(f"unknown top-level key(s): {', '.join(sorted(unknown))}")
        base = cls.preset(doc["preset"]) if "preset" in doc else cls()
        both = _direction_overrides(doc.get("both", {}), "both")
        a_to_b = replace(
            base.a_to_b, **{**both, **_direction_overrides(doc.get("a_to_b", {}), "a_to_b")}
        )
        b_to_a = replace(
            base.b_to_a, **{**both, **_direction_overrides(doc.get("b_to_a", {}), "b_to_a")}
        )
        seed = doc.get("seed", base.seed)
        return cls(a_to_b=a_to_b, b_to_a=b_to_a, seed=seed)


_DIRECTION_FIELDS = {f.name for f in fields(DirectionConfig)}
_FLAG_KEYS = {
    # The command-line flag names (and their dashed long forms) as TOML keys.
    "bits": "bits_per_char",
    "bits-per-char": "bits_per_char",
    "ber": "byte_error_rate",
    "byte-error-rate": "byte_error_rate",
    "outage": "outages",
}
_TEMPLATE_KEYS = ("rate", "bits", "delay", "jitter", "loss", "ber", "noise", "burst", "outage")
"""The keys :meth:`LinkConfig.to_toml` writes: the ``--flag`` names."""
_FAULT_FIELDS = {f.name for f in fields(ScriptedFault)}
_BURST_FIELDS = {f.name for f in fields(GilbertElliott)}


def _as_bytes(name: str, value: Any) -> bytes:
    if isinstance(value, str):
        try:
            return value.encode("latin-1")
        except UnicodeEncodeError:
            raise ConfigError(f"{name} must contain only characters U+0000..U+00FF") from None
    raise ConfigError(f"{name} must be a string, got {value!r}")


def _outages(value: Any, where: str) -> tuple[Outage, ...]:
    """A TOML ``outage`` list: ``[start, end]`` pairs or ``"T1:T2"`` strings."""
    wrong = f'{where}.outages must be a list of [start, end] pairs or "T1:T2" strings'
    if not isinstance(value, list):
        raise ConfigError(f"{wrong}, got {value!r}")
    spans = []
    for entry in value:
        if isinstance(entry, str):
            spans.append(Outage.parse(entry))
        elif isinstance(entry, list) and len(entry) == 2 and all(map(_is_number, entry)):
            spans.append(Outage(float(entry[0]), float(entry[1])))
        else:
            raise ConfigError(f"{wrong}, got {entry!r}")
    return tuple(spans)


def _direction_overrides(table: Any, where: str) -> dict[str, Any]:
    """Translate one TOML direction table into DirectionConfig keyword arguments."""
    if not isinstance(table, Mapping):
        raise ConfigError(f"[{where}] must be a table")
    out: dict[str, Any] = {}
    for key, value in table.items():
        name = _FLAG_KEYS.get(key, key)
        if name not in _DIRECTION_FIELDS:
            raise ConfigError(
                f"unknown key {key!r} in [{where}]; the keys are the command-line flag names "
                f"({', '.join(_TEMPLATE_KEYS)}) or DirectionConfig's field names"
            )
        if name in out:
            raise ConfigError(f"[{where}] gives {name} twice (as {key!r} and another name)")
        out[name] = value
    if isinstance(out.get("burst"), str):
        out["burst"] = GilbertElliott.parse(out["burst"])
    elif "burst" in out:
        burst = out["burst"]
        if not isinstance(burst, Mapping) or set(burst) - _BURST_FIELDS:
            raise ConfigError(f"[{where}.burst] takes only {', '.join(sorted(_BURST_FIELDS))}")
        out["burst"] = GilbertElliott(**burst)
    if "outages" in out:
        out["outages"] = _outages(out["outages"], where)
    if "faults" in out:
        faults = []
        for entry in out["faults"]:
            if not isinstance(entry, Mapping) or set(entry) - _FAULT_FIELDS:
                raise ConfigError(f"{where}.faults entries take only {sorted(_FAULT_FIELDS)}")
            kwargs = dict(entry)
            try:
                kwargs["action"] = FaultAction(kwargs.get("action"))
            except ValueError:
                raise ConfigError(
                    f"{where}.faults action must be drop, corrupt or insert: {entry!r}"
                ) from None
            for key in ("starts_with", "data"):
                if key in kwargs:
                    kwargs[key] = _as_bytes(f"{where}.faults.{key}", kwargs[key])
            faults.append(ScriptedFault(**kwargs))
        out["faults"] = tuple(faults)
    return out


def _toml_value(value: object) -> str:
    """A TOML literal for a number, bool, byte string (each byte one character) or None."""
    if isinstance(value, bool):
        return "true" if value else "false"
    if isinstance(value, bytes):
        return '"' + "".join(_toml_char(b) for b in value) + '"'
    return repr(value)  # an int stays an int; a float keeps its ".0" or exponent


def _toml_char(b: int) -> str:
    if b in (0x22, 0x5C) or b < 0x20 or b >= 0x7F:
        return f"\\u{b:04x}"
    return chr(b)


def _direction_toml(d: DirectionConfig) -> list[str]:
    """One direction's keys, commented, unset ones commented out."""

    def line(key: str, value: str, comment: str, *, on: bool = True) -> str:
        return f"{'' if on else '# '}{key} = {value}".ljust(34) + f"# {comment}"

    out = [
        line(
            "rate",
            _toml_value(d.rate if d.rate is not None else 9600),
            "line rate, bit/s (absent: infinitely fast)",
            on=d.rate is not None,
        ),
        line("bits", _toml_value(d.bits_per_char), "bits per character (8N1 = 10)"),
        line("delay", _toml_value(d.delay), "one-way propagation delay, s"),
        line("jitter", _toml_value(d.jitter), "extra delay, uniform 0..jitter s, never reorders"),
        line("loss", _toml_value(d.loss), "probability a byte vanishes"),
        line("ber", _toml_value(d.byte_error_rate), "probability a byte is corrupted"),
        line("noise", _toml_value(d.noise), "probability a noise byte follows a byte"),
    ]
    if d.burst is None:
        out.append(
            line("burst", '"5e-05:0.05:0.3:0"', "Gilbert-Elliott P_GB:P_BG:E_BAD:E_GOOD", on=False)
        )
    elif d.burst.drop:
        fields_ = ", ".join(
            f"{f.name} = {_toml_value(getattr(d.burst, f.name))}" for f in fields(GilbertElliott)
        )
        out.append(f"burst = {{ {fields_} }}  # Gilbert-Elliott bursts that drop bytes")
    else:
        out.append(line("burst", f'"{d.burst.spec()}"', "Gilbert-Elliott P_GB:P_BG:E_BAD:E_GOOD"))
    if d.outages:
        spans = ", ".join(f'"{o.start!r}:{o.end!r}"' for o in d.outages)
        out.append(f"outage = [{spans}]  # losses of signal, T1:T2 s of link time")
    else:
        out.append(line("outage", '["60:75"]', "losses of signal, T1:T2 s of link time", on=False))
    if d.faults:
        out.append("faults = [" + ", ".join(_fault_toml(f) for f in d.faults) + "]")
    return out


def _fault_toml(fault: ScriptedFault) -> str:
    """A scripted fault as an inline table: its action and every non-default field."""
    parts = [f'action = "{fault.action.value}"']
    for f in fields(ScriptedFault):
        value = getattr(fault, f.name)
        if f.name != "action" and value is not None and value != f.default:
            parts.append(f"{f.name} = {_toml_value(value)}")
    return "{ " + ", ".join(parts) + " }"
