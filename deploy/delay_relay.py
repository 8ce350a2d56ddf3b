#!/usr/bin/env python3
"""A TCP relay that adds a fixed one-way latency in each direction: deploy/scale.sh's stand-in for
`tc netem`, which kernels without the sch_netem module (this project's 2-core machines among them)
refuse. Every chunk read from one side is written to the other `delay_ms` after it arrived, in
order; nothing is throttled or dropped. A link carried through it has an RTT of 2 x delay_ms more
than the network's own.

    delay_relay.py LISTEN_HOST:PORT TARGET_HOST:PORT DELAY_MS

A connection whose target cannot be reached is closed at once (the zenoh router on the other side
retries), so while a partition lasts no connection is held open.
"""

import asyncio
import sys


async def pump(reader, writer, delay_s, loop):
    """Copies reader to writer, each chunk `delay_s` after it arrived."""

    def write(chunk):
        if not writer.is_closing():
            writer.write(chunk)

    try:
        while chunk := await reader.read(1 << 16):
            loop.call_later(delay_s, write, chunk)
            # Back-pressure: a slow far side slows the near one, as a real link does.
            if writer.transport.get_write_buffer_size() > (8 << 20):
                await writer.drain()
    except (ConnectionError, OSError):
        pass


async def main():
    if len(sys.argv) != 4:
        sys.exit("usage: delay_relay.py LISTEN_HOST:PORT TARGET_HOST:PORT DELAY_MS")
    listen_host, listen_port = sys.argv[1].rsplit(":", 1)
    target_host, target_port = sys.argv[2].rsplit(":", 1)
    delay_s = float(sys.argv[3]) / 1000.0
    loop = asyncio.get_running_loop()

    async def handle(near_reader, near_writer):
        try:
            far_reader, far_writer = await asyncio.wait_for(
                asyncio.open_connection(target_host, int(target_port)), timeout=2.0
            )
        except (OSError, asyncio.TimeoutError):
            near_writer.close()
            return
        pumps = [
            asyncio.create_task(pump(near_reader, far_writer, delay_s, loop)),
            asyncio.create_task(pump(far_reader, near_writer, delay_s, loop)),
        ]
        # One side gone: the link is gone (a half-open far side would otherwise linger for minutes).
        _, pending = await asyncio.wait(pumps, return_when=asyncio.FIRST_COMPLETED)
        await asyncio.sleep(delay_s)  # what is still in flight arrives first
        for task in pending:
            task.cancel()
        for writer in (near_writer, far_writer):
            writer.close()

    server = await asyncio.start_server(handle, listen_host, int(listen_port))
    async with server:
        await server.serve_forever()


if __name__ == "__main__":
    try:
        asyncio.run(main())
    except KeyboardInterrupt:
        pass
