"""Hypothesis strategies shared by the serialsocket tests and fuzzers."""

from __future__ import annotations

from hypothesis import strategies as st

from serialsocket.packets import EIGHT_BIT_CLEAN, PRINTABLE, BlockCheck, Encoding

# Payloads rich in the bytes that matter: controls, prefix characters, 8-bit, runs.
interesting_bytes = st.sampled_from(
    [0x00, 0x01, 0x0D, 0x1F, 0x20, 0x23, 0x26, 0x7E, 0x7F, 0x80, 0x8D, 0xA3, 0xFE, 0xFF, 0x41]
)
payloads = st.one_of(
    st.binary(max_size=600),
    st.lists(st.one_of(interesting_bytes, st.integers(0, 255)), max_size=600).map(bytes),
    st.lists(st.tuples(st.integers(0, 255), st.integers(1, 300)), max_size=8).map(
        lambda runs: b"".join(bytes([b]) * n for b, n in runs)
    ),
)

encodings = st.one_of(
    st.sampled_from(
        [PRINTABLE, EIGHT_BIT_CLEAN, Encoding(rept=None), Encoding(qbin=None, rept=None)]
    ),
    st.builds(
        Encoding,
        qctl=st.sampled_from([ord("#"), ord("!"), ord("`")]),
        qbin=st.sampled_from([None, ord("&"), ord(">")]),
        rept=st.sampled_from([None, ord("~"), ord("%")]),
    ),
)

checks = st.sampled_from(list(BlockCheck))


@st.composite
def chunked(draw: st.DrawFn, data: bytes) -> list[bytes]:
    """Split ``data`` at arbitrary points (including empty chunks)."""
    cuts = sorted(draw(st.lists(st.integers(0, len(data)), max_size=12)))
    out, prev = [], 0
    for c in [*cuts, len(data)]:
        out.append(data[prev:c])
        prev = c
    return out
