"""A serial socket in asyncio: a controller and an arm on the two ends of a line.

The line is a pty pair (a null-modem cable inside the machine); with a real
port, pass its path instead (``serial_asyncio.open_serial_socket("/dev/ttyUSB0",
baud=9600)``).  The controller writes three commands and half-closes; the arm
reads to the end, answers each, and closes; both check that every byte was
acknowledged.  Pure asyncio: trio is never imported.

    python examples/asyncio_serial.py
"""

from __future__ import annotations

import asyncio
import sys

import serialsocket.asyncio as serial_asyncio

COMMANDS = [b"MOVE_JOINT 1 20deg", b"STATUS", b"OPEN_FINGERS"]


async def arm(listener: serial_asyncio.AsyncioSerialListener) -> None:
    sock = await listener.accept()
    async with sock:
        commands = (await sock.read()).split(b"\n")[:-1]  # everything, up to the EOF
        print(f"arm: {len(commands)} commands: {' | '.join(c.decode() for c in commands)}")
        for command in commands:
            sock.write(b"DONE " + command + b"\n")
        await sock.drain()
    print(f"arm: closed cleanly: {sock.close_error is None}")


async def controller(port: serial_asyncio.AsyncioSerialPort) -> None:
    async with serial_asyncio.open_serial_socket(port) as sock:
        for command in COMMANDS:
            sock.write(command + b"\n")
        sock.write_eof()  # half-close: the arm sees EOF; our reading goes on
        for reply in (await sock.read()).decode().splitlines():
            print(f"controller: {reply}")
        stats = sock.statistics().link
    print(f"controller: closed cleanly: {sock.close_error is None}")
    print(
        f"controller: {stats.bytes_acknowledged} bytes acknowledged, "
        f"{stats.bytes_delivered} delivered, {stats.packets_sent} packets sent, "
        f"{stats.retransmissions} retransmissions"
    )


async def main() -> None:
    controller_end, arm_end = serial_asyncio.open_pty_pair()
    async with asyncio.timeout(30), serial_asyncio.listen(arm_end) as listener:
        await asyncio.gather(arm(listener), controller(controller_end))
    print(f"trio imported: {'trio' in sys.modules}")


if __name__ == "__main__":
    asyncio.run(main())
