"""Embed the telelink client in ordinary (blocking, threaded) controller code.

``tcpstream.BlockingClient`` runs the async client in a background thread;
every call waits at most ``timeout`` seconds, and the ``watchdog`` ends the
session (the arm halts) if this program stops calling for that long.  To run
as written, this program first starts ``linksim arm-server`` (the simulated
arm) as a separate process on a free loopback port, with a pre-shared key in
a private file.

    python examples/blocking_controller.py
"""

from __future__ import annotations

import json
import math
import os
import secrets
import subprocess
import sys
import tempfile

import tcpstream


def start_arm_server(key_file: str) -> tuple[subprocess.Popen[bytes], int]:
    """Start the simulated arm; it prints one JSON line when it is listening."""
    proc = subprocess.Popen(
        [
            sys.executable,
            "-m",
            "linksim",
            "arm-server",
            "--transport",
            "tcp",
            "--tcp-port",
            "0",
            "--sessions",
            "1",
            "--key-file",
            key_file,
        ],
        stdout=subprocess.PIPE,
    )
    assert proc.stdout is not None
    ready = json.loads(proc.stdout.readline())
    return proc, int(ready["tcp_port"])


def main() -> None:
    key = secrets.token_bytes(32)
    with tempfile.TemporaryDirectory() as tmp:
        key_file = os.path.join(tmp, "arm.key")
        with open(os.open(key_file, os.O_WRONLY | os.O_CREAT, 0o600), "w") as f:
            f.write(key.hex())  # the key file holds the key as hex digits
        proc, port = start_arm_server(key_file)
        try:
            # watchdog: if this thread hangs for 10 s between calls (a deadlock, a
            # stuck sensor read), the client drops the session and the arm halts.
            # The arm's deadman cannot see such a hang: the client's own thread
            # keeps sending heartbeats.
            with tcpstream.BlockingClient.tcp(
                "127.0.0.1", port, key=key, timeout=30, watchdog=10
            ) as arm:
                print("joints:", [round(math.degrees(q), 1) for q in arm.status().feedback.joints])
                arm.move_joint(2, math.radians(-10))
                result = arm.transform_to_pose(arm.status().feedback.joints)
                print("hand at", tuple(round(x, 3) for x in result.feedback.p), "m")
                try:
                    arm.squeeze(10.0)  # nothing between the fingers
                except tcpstream.CommandFailed as exc:
                    print("refused:", exc.reason.name)
        finally:
            proc.wait(timeout=30)


if __name__ == "__main__":
    main()
