"""Pre-shared key files: make one, read one (PROTOCOL.md section 8).

A key file holds the key as hexadecimal digits; whitespace and ``#`` comment
lines are ignored, so a file can say what it is for.  :func:`write_key_file`
creates a new file readable by its owner only and never overwrites one.
"""

from __future__ import annotations

import logging
import os
import secrets
import stat

from ._auth import MIN_KEY_SIZE

__all__ = ["KEY_SIZE", "generate_key", "load_key_file", "write_key_file"]

log = logging.getLogger(__name__)

KEY_SIZE = 32
"""Bytes in a generated key: HMAC-SHA256's block-size-friendly 256 bits."""


def generate_key() -> bytes:
    """A new random key of :data:`KEY_SIZE` bytes from the OS's CSPRNG."""
    return secrets.token_bytes(KEY_SIZE)


def load_key_file(path: str | os.PathLike[str]) -> bytes:
    """The key in ``path`` (hex digits; whitespace and ``#`` lines ignored).

    Raises ``OSError`` if the file cannot be read and ``ValueError`` if it does
    not hold a key of at least 16 bytes, each saying what to do.  A file that
    others may read is used, with a warning: anyone who can read it can
    command the arm.
    """
    with open(path, encoding="ascii", errors="replace") as f:
        mode = os.fstat(f.fileno()).st_mode
        lines = [line.split("#", 1)[0] for line in f]
    text = "".join("".join(lines).split())
    try:
        key = bytes.fromhex(text)
    except ValueError:
        raise ValueError(
            f"{os.fspath(path)}: a key file holds the key as hex digits "
            "(make one with `linksim keygen FILE`)"
        ) from None
    if len(key) < MIN_KEY_SIZE:
        raise ValueError(
            f"{os.fspath(path)}: the key is {len(key)} bytes; at least {MIN_KEY_SIZE} are "
            "needed (make one with `linksim keygen FILE`)"
        )
    if mode & (stat.S_IRWXG | stat.S_IRWXO):
        log.warning("%s can be read by other users: chmod 600 it", os.fspath(path))
    return key


def write_key_file(path: str | os.PathLike[str], key: bytes | None = None) -> bytes:
    """Write ``key`` (default: a new one) to a new file ``path``, mode 0600; return it.

    Never overwrites: an existing file raises ``FileExistsError``.
    """
    key = generate_key() if key is None else key
    if len(key) < MIN_KEY_SIZE:
        raise ValueError(f"a pre-shared key needs at least {MIN_KEY_SIZE} bytes")
    fd = os.open(path, os.O_WRONLY | os.O_CREAT | os.O_EXCL, 0o600)
    with os.fdopen(fd, "w", encoding="ascii") as f:
        f.write("# telelink pre-shared key (hex); keep it secret, give it to both ends\n")
        f.write(key.hex() + "\n")
    return key
