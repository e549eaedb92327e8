"""``GET /estimate`` while idle connections are held: a read deadline and caps that evict
the oldest idle connection, never the new one (127.0.0.1 only, bounded in count)."""

import asyncio
import json

from etobs.runtime.server import HTTP_MAX_PER_ADDRESS, ObserverServer
from etobs.runtime.service import ObserverCore
from tests.estimation import linear
from tests.runtime.loopback import KEYS, _get

IDLE = 200


async def _idle(port, n):
    return [await asyncio.open_connection("127.0.0.1", port) for _ in range(n)]


def _close(conns):
    for _, writer in conns:
        writer.close()


def test_idle_connections_do_not_deny_the_estimate_to_a_client():
    """32 idle TCP connections denied GET /estimate to everyone (0 of 74 answered): the cap
    was taken before the request was read. Now 200 idle ones are held open and every
    legitimate request is answered: a new connection evicts the oldest one still idle."""

    async def main():
        srv = ObserverServer(ObserverCore(linear.factory(), KEYS))
        _, web = await srv.start(http_port=0)
        idle = await _idle(web, IDLE)
        try:
            for _ in range(20):
                await asyncio.sleep(0)  # the server accepts them all
            answers = [await _get(web) for _ in range(74)]
            reading = len(srv._reading)
        finally:
            await srv.close()
            _close(idle)
        return answers, reading

    answers, reading = asyncio.run(main())
    assert [a[0] for a in answers] == ["HTTP/1.0 200 OK"] * 74
    assert json.loads(answers[-1][1])["status"] == "waiting"
    assert reading <= HTTP_MAX_PER_ADDRESS  # the idle ones above the cap were dropped, oldest first


def test_an_idle_connection_is_dropped_at_the_read_deadline():
    """A client that sends nothing is closed once the (injected, short) read deadline passes:
    the test waits for the close, bounded, and asserts no wall time."""

    async def main():
        srv = ObserverServer(ObserverCore(linear.factory(), KEYS), read_timeout=0.05)
        _, web = await srv.start(http_port=0)
        try:
            (reader, writer), *_ = await _idle(web, 1)
            writer.write(b"GET /esti")  # half a request line, then nothing
            await writer.drain()
            data = await asyncio.wait_for(reader.read(), timeout=60)  # only a broken server waits
            answer = await _get(web)
            writer.close()
        finally:
            await srv.close()
        return data, answer

    data, answer = asyncio.run(main())
    assert data == b"" and answer[0] == "HTTP/1.0 200 OK"
